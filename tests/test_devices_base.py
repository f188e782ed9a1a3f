"""The device layer's shared helpers: settings checked against their range, URL options, device keys."""

import doctest

import pytest

from stickslip.devices import base


def test_doctests():
    assert doctest.testmod(base).failed == 0


@pytest.mark.parametrize("value", [0, 5000.5, float("nan"), float("inf"), "fast", None, True])
def test_settings_out_of_range_are_refused_not_clipped(value):
    with pytest.raises(ValueError, match=r"frequency must be a number in 1\.\.5000 Hz, got"):
        base.check_setting("frequency", value, 1, 5000, "Hz")


def test_integer_settings():
    assert base.check_setting("amplitude", 80, 1, 80, integer=True) == 80
    assert isinstance(base.check_setting("amplitude", 7.0, 1, 80, integer=True), int)
    with pytest.raises(ValueError, match="an integer in 1..80"):
        base.check_setting("amplitude", 7.5, 1, 80, integer=True)


def test_url_options():
    assert base.url_options("mm3a:///dev/ttyUSB0?timeout=1&timeout=3", {"timeout"}) == {"timeout": "3"}
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['speed'\].*known: \['timeout'\]"):
        base.url_options("mm3a:///dev/ttyUSB0?speed=3", {"timeout"})


def test_device_key_keeps_identity_and_drops_secrets():
    assert base.device_key("anc300://10.0.0.2:7230?password=123456") == "anc300://10.0.0.2:7230"
    assert base.device_key("mm3a:///dev/ttyUSB0?timeout=5") == "mm3a:///dev/ttyUSB0"
    assert base.device_key("sim://?day=2026-11-22&seed=7") == "sim://?seed=7"
    assert base.device_key("sim://") == "sim://"
    # one simulated arm, one key: the default seed is 0; the physics arm is another arm
    assert base.device_key("sim://?seed=0") == base.device_key("sim://?seed=00") == "sim://"
    assert base.device_key("sim://?physics=1") == base.device_key("sim+physics://?seed=0") == "sim+physics://"
    assert base.device_key("sim+physics://?seed=4&day=x") == "sim+physics://?seed=4"


def test_a_windows_serial_port_is_one_key_however_it_is_written():
    # mm3a://COM3 was kept as 'mm3a://com3' (urlsplit lowers a host) and mm3a:///COM3 as 'mm3a:///COM3': one port,
    # two kept positions and two locks; a move through one spelling planned from the other's stale position
    # (audit39's question)
    keys = {base.device_key(u) for u in ("mm3a://COM3", "mm3a:///COM3", "mm3a://com3?timeout=5", "mm3a:///com3")}
    assert keys == {"mm3a://com3"}
    assert base.device_key("anc300:///COM12?password=x") == base.device_key("anc300://COM12") == "anc300://com12"
    assert base.device_key("mm3a://COM3") != base.device_key("mm3a://COM13") != base.device_key("anc300://COM13")
    assert base.device_key("mm3a:///dev/ttyUSB0") == "mm3a:///dev/ttyUSB0"  # a device file as written
    assert base.device_key("mm3a:///COM3x") == "mm3a:///COM3x"  # not a port name: kept as it stands


def test_step_counts():
    import numpy as np

    assert base.check_steps(-12) == -12 and base.check_steps(np.int64(7)) == 7 and base.check_steps(3.0) == 3
    for bad in (True, 2.5, "10", None, float("nan")):
        with pytest.raises(ValueError, match="step count must be an integer"):
            base.check_steps(bad)


@pytest.mark.parametrize(
    ("url", "hint"),
    [("/dev/ttyUSB0", "mm3a:///dev/ttyUSB0"), ("COM3", "mm3a://COM3"), ("", "mm3a:///dev/ttyUSB0")],
)
def test_a_url_without_scheme_never_opens_the_simulator(url, hint):
    # a bare port used to open sim:// silently: a simulated position in the real arm's place
    with pytest.raises(ValueError, match="has no scheme") as e:
        base.open_device(url)
    assert hint in str(e.value)
    assert base.url_scheme("sim://?seed=3") == "sim" and base.url_scheme("mm3a://COM3") == "mm3a"


def test_a_scheme_less_url_with_a_secret_is_refused_without_the_secret():
    with pytest.raises(ValueError) as e:
        base.open_device("admin:hunter2@10.0.0.2")
    assert "hunter2" not in str(e.value)


@pytest.mark.parametrize(
    ("url", "hint"),
    [("sim:", "write sim://"), ("sim:?seed=3", "write sim://?seed=3"), ("mm3a:/dev/ttyUSB0", "write mm3a:///dev/ttyUSB0")],
)
def test_a_url_missing_its_slashes_is_refused_with_the_url_it_meant(url, hint):
    with pytest.raises(ValueError, match="lacks the //") as e:
        base.open_device(url)
    assert str(e.value).endswith(hint)


@pytest.mark.parametrize(
    ("url", "form", "not_said"),
    [
        ("smaract-mcs2://", "give its network address: smaract-mcs2://192.168.1.200 (the MCS2 is reached over TCP "
         "only)", "/dev/"),
        ("smaract-mcs+socket://", "give its network address: smaract-mcs+socket://192.168.1.5", "/dev/"),
        ("mm3a+socket://", "give the adapter's network address and port: mm3a+socket://192.168.1.20:4001", "/dev/"),
        ("smaract-mcs://", "give the serial port: smaract-mcs:///dev/ttyUSB0 (smaract-mcs://COM3 on Windows; an "
         "MCS's network interface is smaract-mcs+socket://host)", None),
        ("mm3a://", "give the serial port: mm3a:///dev/ttyUSB0 (mm3a://COM3 on Windows; a serial-over-network "
         "adapter is mm3a+socket://host:port)", None),
        ("anc300://", "give its network address (anc300://192.168.1.2) or its serial port (anc300:///dev/ttyUSB0)",
         None),
    ],
)
def test_a_url_without_host_or_port_suggests_its_own_scheme_s_form(url, form, not_said):
    """'smaract-mcs2://' suggested 'smaract-mcs2:///dev/ttyUSB0', but the MCS2 is TCP only (audit26): each scheme's
    message names the form that scheme takes."""
    with pytest.raises(ValueError) as e:
        base.check_device_url(url)
    assert str(e.value) == f"device URL {url!r} names no host and no port: {form}"
    if not_said:
        assert not_said not in str(e.value)


def test_a_backend_registered_with_its_check_has_its_urls_checked_before_use(monkeypatch):
    """A backend added with register_backend got only the URL's shape checked: its options were first read when
    the device opened (audit30's question). With check= they are refused before anything is used or stored."""
    monkeypatch.setattr(base, "BACKENDS", dict(base.BACKENDS))
    monkeypatch.setattr(base, "URL_CHECKS", dict(base.URL_CHECKS))

    def check(url: str) -> None:
        if "rate=0" in url:
            raise ValueError("rate must be > 0 Hz")

    base.register_backend("labstage", lambda url: None, check=check)
    assert base.check_device_url("labstage://10.0.0.9?rate=5") == "labstage://10.0.0.9?rate=5"
    with pytest.raises(ValueError, match="rate must be > 0 Hz"):
        base.check_device_url("labstage://10.0.0.9?rate=0")
    base.register_backend("plainstage", lambda url: None)  # no check: the shape only, as before
    assert base.check_device_url("plainstage://10.0.0.9?rate=0") == "plainstage://10.0.0.9?rate=0"
