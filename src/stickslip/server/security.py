"""Who may talk to the server: the address it binds, the token, the origin of a request.

* **Localhost by default.** Bound to a loopback address (127.0.0.1, ::1, localhost),
  only programs on this machine reach the server, and it asks no token. Requests must
  also name the server by a loopback host (the ``Host`` header), so a web page on
  another site cannot reach it through a name it controls (DNS rebinding).
* **Any other address needs a token**, on every request (``Authorization: Bearer
  TOKEN``) and every WebSocket (the header, or a first message ``{"type": "auth",
  "token": TOKEN}`` from a browser, which cannot set headers on a WebSocket). The token is
  made on first use (:func:`load_or_create_token`), 256 random bits, kept in the user's
  configuration folder in a file only its owner may read (POSIX mode 0600; on Windows the
  folder is in the user's profile, whose permissions admit only that user, the
  administrators and the system), and printed once, when it is made. It is never
  written to a log or sent in a response; it never travels in a URL's query (the page
  takes it from the part after ``#``, which browsers do not send).
* **Cross-origin requests are refused**: a request whose ``Origin`` is not the server
  itself (a page of another site in the same browser) gets 403, and so does a
  WebSocket opened from one.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import secrets
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from .. import records

__all__ = [
    "TOKEN_FILE",
    "Access",
    "default_token_path",
    "is_loopback",
    "load_or_create_token",
    "origin_problem",
]

TOKEN_FILE = "serve-token"
"""The token's file name in the user's configuration folder."""


def default_token_path() -> Path:
    """Where the token is kept: ``platformdirs.user_config_path("stickslip") / "serve-token"``."""
    import platformdirs

    return platformdirs.user_config_path("stickslip", appauthor=False) / TOKEN_FILE


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is this machine only."""
    h = host.strip().strip("[]").lower()
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


TOKEN_WAIT_S = 1.0
"""How long a server waits for the token file another one has just created to be written, s (44 bytes: at once)."""
MAX_TOKEN_BYTES = 1024
"""A token file larger than this is no token file, bytes (a token is 43 characters)."""


def load_or_create_token(path: Path | None = None) -> tuple[str, bool]:
    """The server's token and whether it was made just now (then print it, once).

    The file holds the token alone. A new one is created with owner-only permissions
    (``O_EXCL``, mode 0600: never readable by another user, even for a moment). Raises
    ``OSError`` with the path when the folder cannot be written, ``ValueError`` when the
    file holds no usable token (an empty one too, once :data:`TOKEN_WAIT_S` has passed
    without another server writing its token into it) or is no regular file.
    """
    p = path or default_token_path()
    text = _token_text(p)
    if text is None:
        token = _create_token(p)
        if token is not None:
            return token, True
    if not text:  # created by another server a moment ago (or left empty by one killed before it wrote)
        text = _written_token(p)
    if len(text) < 32 or not text.isascii() or not text.replace("-", "").replace("_", "").isalnum():
        what = "a usable token" if text else "a token (it is empty)"
        raise ValueError(f"{p} does not hold {what} (delete it: a new one is made)")
    return text, False


def _token_text(p: Path) -> str | None:
    """The token file's text, stripped; ``None`` when there is no file (``ValueError`` for one that is no token's)."""
    if not os.path.lexists(p):
        return None
    try:
        return records.read_text_bounded(p, "token", MAX_TOKEN_BYTES).strip()
    except ValueError as e:
        raise ValueError(f"{e} (delete it: a new one is made)") from None


def _written_token(p: Path) -> str:
    """The token another server is writing into ``p``, once written ("" if none is within :data:`TOKEN_WAIT_S`)."""
    end = time.monotonic() + TOKEN_WAIT_S
    while True:
        text = _token_text(p) or ""
        if text or time.monotonic() > end:
            return text
        time.sleep(0.02)


def _create_token(p: Path) -> str | None:
    """A new token written to ``p`` (mode 0600, ``O_EXCL``); ``None`` if another server created the file first."""
    p.parent.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(32)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(p, flags, 0o600)
    except FileExistsError:  # another server made it a moment ago: use that one
        return None
    try:
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(token + "\n")
            f.flush()
            os.fsync(f.fileno())
    except BaseException:  # a full disk: no empty file left, which every later server refused as no token
        p.unlink(missing_ok=True)
        raise
    return token


def origin_problem(origin: str | None, host: str | None) -> str | None:
    """Why a request from page ``origin`` to server ``host`` is refused (``None``: same origin, or no page).

    ``origin`` is the request's ``Origin`` header (absent for a script, ``"null"`` for a
    sandboxed page or a file), ``host`` its ``Host`` header.
    """
    if origin is None:
        return None
    try:
        o = urlsplit(origin)
        same = o.scheme in ("http", "https") and (o.netloc or "").lower() == (host or "").lower()
    except ValueError:
        same = False
    if same:
        return None
    return "cross-origin requests are refused: open the page from this server itself"


@dataclass(frozen=True)
class Access:
    """The server's rules for one run: the token (``None`` on a loopback address) and the bound host."""

    token: str | None
    loopback: bool

    def host_problem(self, host: str | None) -> str | None:
        """Why a request naming ``host`` (its ``Host`` header) is refused on a loopback server (DNS rebinding)."""
        if not self.loopback:
            return None
        name = (host or "").rsplit(":", 1)[0] if not (host or "").startswith("[") else (host or "").split("]")[0] + "]"
        if is_loopback(name):
            return None
        return "this server answers only to a loopback host name (localhost, 127.0.0.1, [::1])"

    def token_problem(self, authorization: str | None) -> str | None:
        """Why a request with this ``Authorization`` header is refused (``None``: no token needed, or the right one)."""
        if self.token is None:
            return None
        if not authorization:
            return "this server needs its token: send 'Authorization: Bearer TOKEN' (the token serve printed)"
        scheme, _, given = authorization.partition(" ")
        if scheme.lower() != "bearer" or not self.accepts(given.strip()):
            return "wrong token (the token serve printed when it made it)"
        return None

    def accepts(self, given: str) -> bool:
        """Whether ``given`` is the token (compared in constant time)."""
        if self.token is None:
            return True
        return hmac.compare_digest(given.encode("utf-8", "replace"), self.token.encode("ascii"))
