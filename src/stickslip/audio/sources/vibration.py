"""Vibration for the limit switch: an accelerometer's stream, from a file or a serial port.

In a vacuum chamber or an SEM there is no air to carry the sound of a step, but the
structure still carries it: an accelerometer (or a piezo disc) on the arm's base picks
up the same clicks and the same change at the end stop. The detector does not care
where its samples come from, so the vibration stream goes through the same
:func:`~stickslip.audio.tuning.tune` and detector as sound: *samples in, end-stop events
out*.

Sources here:

* :func:`read_vibration` - a recording from a file: WAV (any rate and channel count,
  mixed to mono), or CSV with one sample per row (``value`` or ``time_s,value``; the
  sample rate from a ``# sample_rate_hz=...`` comment line, from uniform times, or
  given);
* :class:`SerialSamples` - a live stream of ASCII samples, one per line, from a serial
  port (an Arduino or a DAQ bridge reading the accelerometer): blocks like
  :class:`~stickslip.audio.sources.microphone.Microphone`.

A third kind of sensor, a position read-back, has its own detector
(:class:`~stickslip.audio.readback.ReadbackStopDetector`).

Samples are floats scaled to the sensor's full scale (``full_scale``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...records import regular_file
from ...units import khz_slip
from ..paramfield import param
from .files import AudioSourceError, read_wav

__all__ = ["VIBRATION", "SerialSamples", "VibrationParams", "read_vibration", "sample_rate_ok"]

_RATE = re.compile(r"sample_rate(?:_hz)?\s*[=:]\s*([0-9.eE+]+)")


@dataclass(frozen=True)
class VibrationParams:
    """What a vibration stream may be."""

    sample_rate_range: tuple[float, float] = param(
        (1_000.0, 1_000_000.0), "Hz", "the detector's frame needs kHz; a DAQ gives at most MHz"
    )
    headroom: float = param(1.25, "", "without a full scale, the file's largest magnitude times this maps to 1")


VIBRATION = VibrationParams()


def sample_rate_ok(rate: float, p: VibrationParams = VIBRATION) -> bool:
    """Whether ``rate`` (Hz) is a sample rate a vibration stream may have (``sample_rate_range``)."""
    lo, hi = p.sample_rate_range
    return math.isfinite(rate) and lo <= rate <= hi


def read_vibration(
    path: str | Path, sample_rate: float | None = None, full_scale: float | None = None
) -> tuple[NDArray[np.float32], int]:
    """A vibration recording as ``(samples, sample rate Hz)``: WAV, or CSV of samples.

    Parameters
    ----------
    path : str or Path
        ``.wav`` (read like sound) or ``.csv``/``.txt``: one sample per row, either
        ``value`` or ``time_s,value``; lines starting with ``#`` are comments, and one of
        them may say ``sample_rate_hz=25000``; a header row of names is skipped.
    sample_rate : float, optional
        Samples per second, Hz; needed for a CSV of values without a rate comment.
    full_scale : float, optional
        Value that maps to 1.0 (e.g. the accelerometer's range in m/s^2); default: the
        file's largest magnitude times 1.25 (so every sample lies within full scale).

    Raises
    ------
    AudioSourceError
        The file is missing or unreadable, has no samples, non-uniform times, or no rate.
    """
    p = Path(path)
    if p.suffix.lower() == ".wav":
        return read_wav(p)
    rows, rate, names, commas = _csv_rows(p, sample_rate)
    data = np.asarray(rows, dtype=np.float64)
    if data.shape[1] == 2:
        _check_time_name(p, names)
        t, x = data[:, 0], data[:, 1]
        dt = np.diff(t)
        if dt.size == 0 or not np.all(dt > 0) or float(np.ptp(dt)) > 1e-3 * float(np.mean(dt)):
            raise AudioSourceError(commas or f"{p}: the times are not uniformly spaced (resample first)")
        said = 1.0 / float(np.mean(dt))
        if rate is not None and abs(said - rate) > 1e-3 * rate:
            raise AudioSourceError(
                f"{p}: its times say {said:.6g} Hz but {rate:g} Hz is given (--sample-rate or a sample_rate_hz line): "
                "keep the one that is right"
            )
        rate = rate or said
    else:
        x = data[:, 0]
    if rate is None:
        raise AudioSourceError(f"{p}: no sample rate: add a '# sample_rate_hz=...' line, or give it (--sample-rate)")
    if not sample_rate_ok(rate):
        raise AudioSourceError(f"{p}: sample rate {rate:g} Hz is outside 1000-1000000 Hz{khz_slip(rate, 1e3, 1e6)}")
    if not np.all(np.isfinite(x)):
        k = int(np.argmax(~np.isfinite(x)))
        raise AudioSourceError(f"{p}: data row {k + 1} holds {float(x[k])!r}, not a finite number")
    fs = float(full_scale) if full_scale else VIBRATION.headroom * float(np.max(np.abs(x))) or 1.0
    y = x / fs
    if not math.isfinite(fs) or not np.all(np.abs(y) <= np.finfo(np.float32).max):
        k = int(np.argmax(np.abs(x)))
        raise AudioSourceError(f"{p}: data row {k + 1} holds {float(x[k])!r}, too large for a sample")
    return y.astype(np.float32), int(round(rate))


_TIME_NAME = re.compile(r"(?:time|t)(?:\s*[_\[(]\s*(?P<unit>[^\])\s]*)\s*[\])]?)?", re.IGNORECASE)


def _check_time_name(p: Path, names: list[str] | None) -> None:
    """Refuse a header whose time column is second, or whose times are not in seconds (``time_ms``, ``t [us]``)."""
    if names is None or len(names) != 2:
        return
    first, second = (_TIME_NAME.fullmatch(n.strip()) for n in names)
    if first is None and second is not None:
        raise AudioSourceError(
            f"{p}: the header names {names[0]!r},{names[1]!r}: the time column comes first (time_s,value)"
        )
    if first is not None and (first.group("unit") or "s").lower() not in ("s", "sec", "seconds"):
        raise AudioSourceError(
            f"{p}: the time column is named {names[0]!r}: times are read in seconds: convert them and name the "
            "column time_s"
        )


def _names(line: str) -> list[str]:
    """A header row's column names: split at its commas, semicolons or tabs (a name may hold a space: 'time (ms)')."""
    sep = r"[,;\t]" if re.search(r"[,;\t]", line) else r"\s+"
    return [n.strip() for n in re.split(sep, line) if n.strip()]


_DECIMAL_COMMA = re.compile(r"[+-]?\d+,\d+(?:[eE][+-]?\d+)?(?:[;\t ]+[+-]?\d+,\d+(?:[eE][+-]?\d+)?)*")
"""A data line whose every number is written with a decimal comma (0,0021 or 0,00004;0,0021)."""


def _csv_rows(
    p: Path, sample_rate: float | None
) -> tuple[list[list[float]], float | None, list[str] | None, str | None]:
    """The rows of numbers of a CSV of samples, its rate (``sample_rate``, or its ``# sample_rate_hz=`` line), its
    header row's names (None without one), and, when every data line is numbers written with decimal commas (a
    spreadsheet in German or French), the refusal to give should the rows not read as samples (else None)."""
    try:
        if p.exists():
            regular_file(p, "CSV of samples")  # a folder, FIFO or device is never opened
        text = p.read_text(encoding="utf-8-sig")  # a byte order mark (Excel's UTF-8) is not part of the first line
    except UnicodeDecodeError as e:  # before ValueError, of which it is one
        raise AudioSourceError(f"{p}: not UTF-8 text (byte {e.object[e.start]:#04x} at offset {e.start}): "
                               "save the CSV as UTF-8") from None
    except ValueError as e:
        raise AudioSourceError(str(e)) from None
    except FileNotFoundError:
        raise AudioSourceError(f"{p}: no such file") from None
    except OSError as e:
        raise AudioSourceError(f"{p}: cannot read ({e.strerror or e})") from None
    rate = sample_rate
    said: float | None = None
    rows: list[list[float]] = []
    names: list[str] | None = None
    commas: str | None = None  # the refusal for decimal commas, while every data line holds them
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            said = _rate_comment(p, lineno, s, said)
            continue
        parts = [x for x in re.split(r"[,;\s]+", s) if x]
        try:
            rows.append([float(x) for x in parts])
            if len(rows) == 1 and _DECIMAL_COMMA.fullmatch(s):
                commas = (f"{p}:{lineno}: {s!r} is written with decimal commas: save the samples with decimal "
                          "points (0.0021, not 0,0021)")
            elif commas and not _DECIMAL_COMMA.fullmatch(s):
                commas = None
        except ValueError:
            if not rows:
                names = names or _names(s)  # a header row of column names
                continue
            raise AudioSourceError(f"{p}:{lineno}: not a number in {s!r}") from None
    if not rows:
        raise AudioSourceError(f"{p}: no samples")
    rate = rate if rate is not None else said
    width = {len(r) for r in rows}
    if len(width) != 1 or width.pop() not in (1, 2):
        raise AudioSourceError(commas or f"{p}: every row must hold 'value' or 'time_s,value'")
    return rows, rate, names, commas


def _rate_comment(p: Path, lineno: int, line: str, said: float | None) -> float | None:
    """The rate a ``# sample_rate_hz=...`` comment says, Hz (``said``: an earlier one's, which it must repeat)."""
    m = _RATE.search(line)
    if m is None:
        return said
    try:
        rate = float(m.group(1))
    except ValueError:
        raise AudioSourceError(f"{p}:{lineno}: the sample rate {m.group(1)!r} is not a number") from None
    if said is not None and rate != said:
        raise AudioSourceError(f"{p}:{lineno}: a second sample rate, {rate:g} Hz after {said:g} Hz: keep one")
    return rate


class SerialSamples:
    """A live vibration stream: ASCII samples, one per line, from a serial port.

    Parameters
    ----------
    port : str
        Serial port (``/dev/ttyACM0``, ``COM3``) or a pyserial URL (``loop://`` for tests).
    sample_rate : int
        The sensor's sample rate, Hz (the stream carries no clock of its own).
    block : int
        Samples per block handed out.
    full_scale : float
        Value that maps to 1.0.
    baudrate : int
        Serial speed, baud.
    serial : object, optional
        An open pyserial-like object (``readline()``); overrides ``port``.

    Raises
    ------
    AudioSourceError
        When the port cannot be opened, a line is not a number, or nothing comes for
        ``timeout_s``.
    """

    def __init__(
        self,
        port: str = "",
        sample_rate: int = 25_000,
        block: int = 1024,
        full_scale: float = 1.0,
        baudrate: int = 921_600,
        serial: Any = None,
        timeout_s: float = 2.0,
    ) -> None:
        self.sample_rate = int(sample_rate)
        self.block = int(block)
        self.full_scale = float(full_scale)
        self.timeout_s = float(timeout_s)
        if serial is None:
            try:
                import serial as pyserial
            except ImportError as e:  # pragma: no cover - pyserial is a core dependency
                raise AudioSourceError("a serial vibration source needs pyserial") from e
            try:
                serial = pyserial.serial_for_url(port, baudrate=baudrate, timeout=timeout_s)
            except (OSError, ValueError) as e:
                raise AudioSourceError(f"cannot open {port}: {e}") from None
        self._serial = serial

    def blocks(self) -> Iterator[NDArray[np.float32]]:
        """Yield blocks of ``block`` samples (scaled by ``full_scale``) as they arrive."""
        buf: list[float] = []
        while True:
            line = self._serial.readline()
            if not line:
                raise AudioSourceError(f"no vibration samples for {self.timeout_s:g} s")
            s = line.decode("ascii", "replace").strip() if isinstance(line, bytes) else str(line).strip()
            if not s:
                continue
            try:
                v = float(s.split(",")[-1])
            except ValueError:
                raise AudioSourceError(f"not a sample: {s[:40]!r}") from None
            if not math.isfinite(v):
                raise AudioSourceError(f"not a finite sample: {s[:40]!r}")
            buf.append(v / self.full_scale)
            if len(buf) >= self.block:
                yield np.asarray(buf, dtype=np.float32)
                buf = []

    def __iter__(self) -> Iterator[NDArray[np.float32]]:
        return self.blocks()

    def close(self) -> None:
        """Close the port."""
        close = getattr(self._serial, "close", None)
        if close is not None:
            close()
