"""The URLs docs/devices/*.md and docs/howto/anc300.md show are ones stickslip takes (checked without opening
anything).

A user copies these first; a URL a page shows that the driver refuses leaves them stuck. The pages' commands
run elsewhere: docs/howto/anc300.md's in tests/test_anc300.py, the protocols by the peers (tests/support).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from stickslip.devices.base import check_device_url

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGES = ["devices/smaract.md", "devices/nanocontrol.md", "howto/anc300.md"]


def _urls(page: str) -> list[str]:
    """Each URL at the start of a line of the page's ```text blocks (a line's comment after two spaces cut)."""
    text = (DOCS / page).read_text(encoding="utf-8")
    lines = [ln for block in re.findall(r"```text\n(.*?)```", text, re.S) for ln in block.splitlines()]
    words = [w for ln in lines for w in ln.split("  ")[0].split()]
    return [w for w in words if re.match(r"^[a-z0-9+-]+://", w)]


@pytest.mark.parametrize("page", PAGES)
def test_every_url_a_device_page_shows_is_taken(page: str) -> None:
    urls = _urls(page)
    assert len(urls) >= 2, urls
    for url in urls:
        assert check_device_url(url) == url
