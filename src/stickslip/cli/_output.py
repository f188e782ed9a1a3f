"""The one way out of the command line: what reaches a terminal, a pipe or a file, and how a failed write ends.

The rules (docs/cli.md, "Output"):

* **Text is shown, never interpreted.** The consoles of this module have rich's markup
  and emoji off: a label, path or device URL holding ``[/]`` or ``:smile:`` is printed as
  it stands. Styles are set with :func:`styled` (a rich ``Text``), never by markup in a
  string that may hold user text.
* **Nothing raw reaches the terminal.** Every string a console prints passes through
  :func:`visible`: a control character (``ESC``, CR, BEL, the C1 controls), a
  bidirectional override or isolate (``U+202E``), a line separator or a lone surrogate is
  shown as its Python escape (``\\x1b``, ``\\r``, ``\\u202e``), so no input can clear the
  screen, move the cursor, retitle the window or reverse the text around it.
* **No secret is printed.** Every string a console prints, and every error and warning
  line, passes through :func:`stickslip.devices.base.redact_text` (the redaction of
  :func:`~stickslip.devices.base.redact_url`, applied to each URL in a message).
* **Units degrade where the stream cannot encode them.** On a stream whose encoding
  lacks ``µ`` (an ASCII locale, a Windows code page) ``µm`` is written ``um``, ``±`` as
  ``+/-``, ``°`` as ``deg`` (:data:`ASCII_FALLBACK`); any other character it lacks as its
  escape. Data (``--json``, CSV on standard output) is never changed: JSON is ASCII, and
  a CSV cell the stream cannot encode ends the command with one line naming the encoding.
* **A failed write is an error; a closed pipe is a quiet end.** A write to standard
  output or error that fails raises :class:`OutputError` (not an ``OSError``, so no
  command mistakes it for a problem with its input). The command group ends it: a reader
  that went away (``EPIPE``: ``stickslip history | head``) ends the command quietly with
  exit 1, as Python's own tools do; any other failure (a full device, an I/O error) is one
  ``error:`` line and exit 2, since the output is incomplete.
"""

from __future__ import annotations

import errno
import io
import os
import re
import sys
import unicodedata
from collections.abc import Iterable
from functools import lru_cache
from typing import TYPE_CHECKING, Any, TextIO, cast

from rich.console import Console
from rich.control import Control
from rich.segment import ControlType, Segment
from rich.text import Text

from ..devices.base import redact_text

if TYPE_CHECKING:
    from rich.console import ConsoleOptions, RenderableType
    from rich.style import Style

__all__ = [
    "ASCII_FALLBACK",
    "CARRIAGE_RETURN",
    "OutputError",
    "SafeConsole",
    "console",
    "data_stream",
    "err_console",
    "finish",
    "silence",
    "styled",
    "visible",
]

ASCII_FALLBACK = {
    "µ": "u", "μ": "u", "±": "+/-", "°": "deg", "—": "-", "–": "-", "−": "-", "◀": "<", "▶": ">",
    "×": "x", "…": "...", "≤": "<=", "≥": ">=", "≈": "~", "→": "->", "←": "<-", "·": "*",
    "α": "alpha", "β": "beta", "γ": "gamma", "δ": "delta", "Δ": "Delta", "ζ": "zeta", "η": "eta",
    "θ": "theta", "π": "pi", "σ": "sigma", "ψ": "psi", "²": "^2", "³": "^3",
    "‘": "'", "’": "'", "“": '"', "”": '"', "✓": "ok", "✗": "x",
}  # fmt: skip
"""What a character the output stream cannot encode is written as (any other: its escape)."""

_ASCII_UNSAFE = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")


def _escape(c: str) -> str:
    """A character as Python writes it in a string literal (``\\x1b``, ``\\u202e``)."""
    return repr(c)[1:-1]


def _shown(c: str) -> bool:
    """Whether ``c`` may reach a terminal as it is (a printable character, a line feed or a tab)."""
    return c.isprintable() or c in "\n\t"


@lru_cache(maxsize=16)
def _encodable(encoding: str) -> Any:
    """A function: whether one character can be encoded in ``encoding`` (cached per character)."""

    @lru_cache(maxsize=4096)
    def can(c: str) -> bool:
        try:
            c.encode(encoding)
        except (UnicodeEncodeError, LookupError):
            return False
        return True

    return can


def visible(text: str, encoding: str | None = None) -> str:
    """``text`` safe for a terminal: controls and bidirectional marks as escapes, units in ``encoding``.

    A character that is not printable (a control character, a bidirectional override,
    a line separator, a surrogate) becomes its Python escape (``\\x1b``, ``\\u202e``); the
    line feed and the tab stay. With ``encoding``, a character the encoding lacks becomes
    its :data:`ASCII_FALLBACK` (``µ`` -> ``u``) or else its escape.

    >>> visible("day\\x1b[2J \\u202eevil")
    'day\\\\x1b[2J \\\\u202eevil'
    >>> visible("5 µm ± 2 °", "ascii")
    '5 um +/- 2 deg'
    """
    if text.isascii():
        if _ASCII_UNSAFE.search(text) is None:
            return text
        return _ASCII_UNSAFE.sub(lambda m: _escape(m.group(0)), text)
    utf = encoding is None or encoding.replace("-", "").replace("_", "").lower().startswith("utf")
    can = None if utf else _encodable(encoding.lower())  # type: ignore[union-attr]  # not None when not utf
    out = []
    for c in text:
        if c.isascii():
            out.append(c if not _ASCII_UNSAFE.match(c) else _escape(c))
        elif not _shown(c):
            out.append(_escape(c))
        elif can is not None and not can(c):
            fallback = ASCII_FALLBACK.get(c)
            if fallback is None:
                plain = unicodedata.normalize("NFKD", c)
                plain = "".join(x for x in plain if not unicodedata.combining(x))
                if not (plain and all(can(x) for x in plain)):
                    plain = c.encode("ascii", "backslashreplace").decode()
                fallback = plain
            out.append(fallback)
        else:
            out.append(c)
    return "".join(out)


# ---------------------------------------------------------------- the streams


class OutputError(Exception):
    """A write to standard output or standard error failed.

    ``closed`` is true when the reader went away (``EPIPE``: a pipe into ``head`` that
    ended), which ends a command quietly; otherwise the output is incomplete and the
    command ends with ``error:`` and exit 2. Not an ``OSError`` on purpose: a command's
    ``except OSError`` is about its files and devices, never about its own output.
    """

    def __init__(self, stream: str, error: BaseException) -> None:
        self.stream = stream
        self.errno = getattr(error, "errno", None)
        self.closed = self.errno in (errno.EPIPE, errno.ECONNRESET) or isinstance(error, BrokenPipeError)
        reason = getattr(error, "strerror", None) or str(error) or type(error).__name__
        super().__init__(f"cannot write to the {stream}: {reason}")


_NAMES = {"stdout": "standard output", "stderr": "standard error"}
_CHUNK = 1 << 15


class _Stream(io.TextIOBase):
    """``sys.stdout`` or ``sys.stderr`` as they are at each write (tests swap them), with checked writes.

    ``text=True`` (the consoles): a string the stream cannot encode is written with
    :func:`visible` in its encoding. ``text=False`` (data): it raises :class:`OutputError`;
    data written to a terminal (not a pipe or file) has its control characters escaped.
    Any ``OSError`` (a closed pipe, a full device) raises :class:`OutputError`.
    """

    def __init__(self, name: str, text: bool = True) -> None:
        super().__init__()
        self._name = name
        self._text = text

    @property
    def _raw(self) -> Any:
        # A progress bar on a terminal points sys.stdout/stderr at a rich proxy that prints through the bar's
        # console, whose file is this stream: writing to the proxy would feed the console into itself
        # (RecursionError). The stream under the proxy is the one to write to, as rich's own Console.file does.
        raw = getattr(sys, self._name)
        return getattr(raw, "rich_proxied_file", raw)

    @property
    def encoding(self) -> str:  # type: ignore[override]  # io.TextIOBase declares it read-only
        return str(getattr(self._raw, "encoding", None) or "utf-8")

    def write(self, s: str) -> int:
        if len(s) > _CHUNK:  # an unbuffered stream (PYTHONUNBUFFERED) drops what one short write to a pipe left
            return sum(self.write(s[i : i + _CHUNK]) for i in range(0, len(s), _CHUNK))
        if not self._text and self.isatty():  # data on a terminal is read by a person: no raw controls either
            s = visible(s)
        try:
            try:
                return int(self._raw.write(s) or 0)
            except UnicodeEncodeError as e:
                if not self._text:
                    c = e.object[e.start]
                    what = f"U+{ord(c):04X} ({unicodedata.name(c, 'a character').lower()})"
                    raise OutputError(
                        _NAMES[self._name],
                        ValueError(
                            f"its encoding {self.encoding} cannot write {what} in the data; write to a file with "
                            "-o/--output (UTF-8), or set PYTHONIOENCODING=utf-8"
                        ),
                    ) from None
                return int(self._raw.write(visible(s, self.encoding)) or 0)
        except OSError as e:
            raise OutputError(_NAMES[self._name], e) from None
        except ValueError as e:  # "I/O operation on closed file"
            if isinstance(e, UnicodeError):
                raise
            raise OutputError(_NAMES[self._name], e) from None

    def flush(self) -> None:
        try:
            self._raw.flush()
        except OSError as e:
            raise OutputError(_NAMES[self._name], e) from None
        except ValueError as e:
            raise OutputError(_NAMES[self._name], e) from None

    def isatty(self) -> bool:
        try:
            return bool(self._raw.isatty())
        except (AttributeError, ValueError, OSError):
            return False

    def fileno(self) -> int:
        return int(self._raw.fileno())

    def writable(self) -> bool:
        return True

    def close(self) -> None:
        """Nothing: the standard streams are not ours to close (and a finalizer must not flush them)."""


_DATA = _Stream("stdout", text=False)


def data_stream() -> TextIO:
    """Standard output for data (``--json``, CSV): written unchanged; a failed write raises :class:`OutputError`."""
    return cast(TextIO, _DATA)


def finish() -> None:
    """Flush standard output and error (:class:`OutputError` if that fails): a command's output is complete."""
    _Stream("stdout").flush()
    _Stream("stderr").flush()


def silence(stream: str = "stdout") -> None:
    """Point a failed standard stream at the null device, so that Python's own flush at exit says nothing.

    Where the stream has no file descriptor (a test's stream) nothing is done.
    """
    raw = getattr(sys, stream)
    try:
        fd = raw.fileno()
        null = os.open(os.devnull, os.O_WRONLY)
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        return
    try:
        os.dup2(null, fd)
    except OSError:
        pass
    finally:
        os.close(null)


# ---------------------------------------------------------------- the consoles


class SafeConsole(Console):
    """A rich console for people: markup and emoji off, every string redacted and made :func:`visible`.

    ``render_str`` (every string printed, every table cell and title) and ``render``
    (every segment of any renderable: a safety net under ``Text`` objects built elsewhere)
    apply the output rules; the file is standard output or error through :class:`_Stream`.
    """

    def __init__(self, stderr: bool = False, **kwargs: Any) -> None:
        kwargs.setdefault("markup", False)
        kwargs.setdefault("emoji", False)
        kwargs.setdefault("file", _Stream("stderr" if stderr else "stdout"))
        super().__init__(stderr=stderr, **kwargs)

    def render_str(
        self,
        text: str,
        *,
        style: str | Style = "",
        justify: Any = None,
        overflow: Any = None,
        emoji: bool | None = None,
        markup: bool | None = None,
        highlight: bool | None = None,
        highlighter: Any = None,
    ) -> Text:
        return super().render_str(
            visible(redact_text(text), self.encoding),
            style=style,
            justify=justify,
            overflow=overflow,
            emoji=emoji,
            markup=markup,
            highlight=highlight,
            highlighter=highlighter,
        )

    def render(self, renderable: RenderableType, options: ConsoleOptions | None = None) -> Iterable[Segment]:
        encoding = self.encoding
        for seg in super().render(renderable, options):
            if seg.control or (seg.text.isascii() and _ASCII_UNSAFE.search(seg.text) is None):
                yield seg
            else:
                yield Segment(visible(seg.text, encoding), seg.style, seg.control)


def styled(text: object, style: str | Style) -> Text:
    """``text`` (redacted, :func:`visible`) in ``style``: the way to bold or colour text that may hold user input."""
    return Text(visible(redact_text(str(text))), style=style)


console = SafeConsole()
"""Standard output, for people (tables, summaries)."""
err_console = SafeConsole(stderr=True)
"""Standard error: progress, warnings, errors."""

CARRIAGE_RETURN = Control(ControlType.CARRIAGE_RETURN)
"""Back to the start of the line (a live meter redrawn in place): a control, not text, so it is never escaped."""
