"""A password in a device URL is never printed, whatever characters it holds (docs/threat-model.md).

A password written unencoded may hold ``@``, ``/``, ``?`` or ``#``; urllib then reads part of it as the host or
the port, and its own error message quotes that part ("Port could not be cast to integer value as 'pa'").
"""

from __future__ import annotations

import string
from urllib.parse import quote

import pytest
from hypothesis import given
from hypothesis import strategies as st

from stickslip.devices.base import check_device_url, device_key, redact_text, redact_url

# what a password may hold inside a URL pasted into text: anything but a space and the quotes and angle
# brackets that end a URL in running text (redact_text's boundary; the threat model's known gaps)
PASSWORD_CHARS = "".join(c for c in string.printable if not c.isspace() and c not in "'\"<>")
USER = st.text(string.ascii_letters + string.digits + "._-", max_size=8)
PASSWORD = st.text(PASSWORD_CHARS, min_size=1, max_size=24)


@given(USER, PASSWORD)
def test_a_password_of_any_characters_is_redacted_to_the_last_at(user, password):
    url = f"anc300://{user}:{password}@10.0.0.2:7230?axes=1,2,3"
    assert redact_url(url) == f"anc300://{user}:***@10.0.0.2:7230?axes=1,2,3"
    assert redact_text(f"opening {url} failed") == f"opening anc300://{user}:***@10.0.0.2:7230?axes=1,2,3 failed"
    assert redact_url(f"{user}:{password}@10.0.0.2") == (
        f"{user}:***@10.0.0.2" if password[0] not in "/\\" else f"{user}:{password}@10.0.0.2"
    )


@given(USER, PASSWORD.filter(lambda p: len(p) >= 4))
def test_a_url_whose_password_hides_its_host_is_refused_without_a_piece_of_it(user, password):
    """Refused or read, the message never holds the password nor the piece urllib quotes as a port."""
    url = f"anc300://{user}:{password}@10.0.0.2:7230"
    for read in (check_device_url, device_key):
        try:
            read(url)
        except ValueError as e:
            assert password not in str(e) and "could not be cast" not in str(e)


@pytest.mark.parametrize("password", ["pa/ss", "pa#ss", "pa?ss"])
def test_a_password_with_a_slash_is_named_as_the_cause_not_the_port(password):
    with pytest.raises(ValueError) as e:
        check_device_url(f"anc300://admin:{password}@10.0.0.2:7230")
    assert str(e.value) == (
        "malformed device URL 'anc300://admin:***@10.0.0.2:7230': its user:password@ part hides the host (a "
        "password holding @ / ? # must be percent-encoded: / as %2F, @ as %40)"
    )
    assert device_key(f"anc300://admin:{quote(password, safe='')}@10.0.0.2:7230") == "anc300://10.0.0.2:7230"


@pytest.mark.parametrize("path", ["C:/Users/lab/run@2.csv", "C:\\Users\\lab\\run@2.csv", "D:/a:b@c"])
def test_a_windows_path_with_an_at_is_left_as_it_is(path):
    assert redact_text(f"cannot read {path}") == f"cannot read {path}"


@pytest.mark.parametrize("url", ["files://a.png?pixel=1um&token=hunter2", "files://a.png?token=hunter2"])
def test_a_camera_urls_message_keeps_its_end_with_the_secret_hidden(url):
    """A message is redacted URL by URL: the secret hidden, the rest of the line (the known options) kept."""
    from stickslip.vision.camera import open_camera

    with pytest.raises(ValueError) as e:
        open_camera(url)
    text = str(e.value)
    assert "hunter2" not in text
    assert "token=***'" in text and text.endswith("'pixel'])")


@pytest.mark.parametrize("url", ["anc300://127.0.0.1:1?hz=abc&password=hunter2",
                                 "smaract-mcs2://127.0.0.1:1?x=1&password=hunter2"])
def test_a_device_urls_message_keeps_its_end_with_the_secret_hidden(url):
    """open_device redacted a driver's message as one URL: 'where -d anc300://H?hz=abc&password=...' said
    "unknown option(s) ['hz'] in 'anc300://H?hz=abc&password=***" and nothing of the known options."""
    from stickslip.devices.base import open_device

    with pytest.raises(ValueError) as e:
        open_device(url)
    text = str(e.value)
    assert "hunter2" not in text
    assert "password=***' (known: [" in text and text.endswith("])"), text
