"""Other sensors for the limit switch: vibration (an accelerometer) and position read-back.

In a vacuum chamber or an SEM there is no air to carry the sound of a step, but the
structure still carries it: an accelerometer (or a piezo disc) on the arm's base picks
up the same clicks and the same change at the end stop. The detector does not care
where its samples come from, so the vibration stream goes through the same
:func:`~stickslip.audio.tuning.tune` and :class:`~stickslip.audio.detector.StopDetector`
as sound: *samples in, end-stop events out*.

Sources here:

* :func:`read_vibration` - a recording from a file: WAV (any rate and channel count,
  mixed to mono), or CSV with one sample per row (``value`` or ``time_s,value``; the
  sample rate from a ``# sample_rate_hz=...`` comment line, from uniform times, or
  given);
* :class:`SerialSamples` - a live stream of ASCII samples, one per line, from a serial
  port (an Arduino or a DAQ bridge reading the accelerometer): blocks like
  :class:`~stickslip.audio.sources.Microphone`;
* :class:`ReadbackStopDetector` - a third kind of sensor, a position read-back (a
  capacitive sensor, an encoder): fed position samples, it reports a stop when the
  position stops changing while the joint is stepping. Same interface as the detector.

Samples are floats scaled to the sensor's full scale (``full_scale``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..records import regular_file
from .detector import StopEvent
from .sources import AudioSourceError, read_wav

__all__ = ["ReadbackStopDetector", "SerialSamples", "read_vibration"]

_RATE = re.compile(r"sample_rate(?:_hz)?\s*[=:]\s*([0-9.eE+]+)")


#: sample rates a vibration stream may have, Hz (the detector's frame needs kHz; a DAQ gives at most MHz)
SAMPLE_RATE_RANGE = (1_000.0, 1_000_000.0)


def sample_rate_ok(rate: float) -> bool:
    """Whether ``rate`` (Hz) is a sample rate a vibration stream may have (:data:`SAMPLE_RATE_RANGE`)."""
    lo, hi = SAMPLE_RATE_RANGE
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
    try:
        if p.exists():
            regular_file(p, "CSV of samples")  # a folder, FIFO or device is never opened
        text = p.read_text(encoding="utf-8")
    except ValueError as e:
        raise AudioSourceError(str(e)) from None
    except FileNotFoundError:
        raise AudioSourceError(f"{p}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise AudioSourceError(f"{p}: cannot read ({e})") from None
    rate = sample_rate
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = _RATE.search(s)
            if m and rate is None:
                rate = float(m.group(1))
            continue
        parts = [x for x in re.split(r"[,;\s]+", s) if x]
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            if not rows:
                continue  # a header row of column names
            raise AudioSourceError(f"{p}:{lineno}: not a number in {s!r}") from None
    if not rows:
        raise AudioSourceError(f"{p}: no samples")
    width = {len(r) for r in rows}
    if len(width) != 1 or width.pop() not in (1, 2):
        raise AudioSourceError(f"{p}: every row must hold 'value' or 'time_s,value'")
    data = np.asarray(rows, dtype=np.float64)
    if data.shape[1] == 2:
        t, x = data[:, 0], data[:, 1]
        dt = np.diff(t)
        if dt.size == 0 or not np.all(dt > 0) or float(np.ptp(dt)) > 1e-3 * float(np.mean(dt)):
            raise AudioSourceError(f"{p}: the times are not uniformly spaced (resample first)")
        rate = rate or 1.0 / float(np.mean(dt))
    else:
        x = data[:, 0]
    if rate is None:
        raise AudioSourceError(f"{p}: no sample rate: add a '# sample_rate_hz=...' line, or give it (--sample-rate)")
    if not sample_rate_ok(rate):
        raise AudioSourceError(f"{p}: sample rate {rate:g} Hz is outside 1000-1000000 Hz")
    if not np.all(np.isfinite(x)):
        k = int(np.argmax(~np.isfinite(x)))
        raise AudioSourceError(f"{p}: data row {k + 1} holds {float(x[k])!r}, not a finite number")
    fs = float(full_scale) if full_scale else 1.25 * float(np.max(np.abs(x))) or 1.0
    return (x / fs).astype(np.float32), int(round(rate))


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


class ReadbackStopDetector:
    """End stops from a position read-back: the position stops changing while stepping.

    Feed it position samples (any unit, sampled at ``sample_rate``) the way the audio
    detector is fed sound; it fires when the position has moved less than
    ``min_motion`` over the last ``window_s`` after having moved, and estimates the
    onset as the time of the last sample that still moved. A controller whose "counter"
    counts the steps *issued* (NanoControl's ``counterread``) cannot serve: it keeps
    counting against the stop; only a sensor of the slider's position can.

    Parameters
    ----------
    sample_rate : float
        Position samples per second, Hz.
    min_motion : float
        Smallest change of position over ``window_s`` that counts as moving (position unit).
    window_s : float
        Stall time that makes a stop, s (the latency is about this).
    t0_s : float
        Stream time of the first sample, s.
    """

    uses_audio = False  # the no-signal guard is for sound and vibration, not positions

    def __init__(self, sample_rate: float, min_motion: float, window_s: float = 0.02, t0_s: float = 0.0) -> None:
        if not (sample_rate > 0 and min_motion > 0 and window_s > 0):
            raise ValueError("sample_rate, min_motion and window_s must be > 0")
        self.sample_rate = float(sample_rate)
        self.min_motion = float(min_motion)
        self.window_s = float(window_s)
        self.reset(t0_s)

    @property
    def latency_s(self) -> float:
        """Typical detected_at - onset, s."""
        return self.window_s

    def reset(self, t0_s: float = 0.0) -> None:
        """Forget everything; the next sample is at stream time ``t0_s``."""
        self._t0 = float(t0_s)
        self._n = 0
        self._recent: list[float] = []
        self._anchor: float | None = None
        self._anchor_i = 0
        self._moved = False
        self.latched = False

    def feed(self, block: NDArray[np.floating[Any]] | list[float]) -> list[StopEvent]:
        """Consume position samples; return the stops that fired."""
        out: list[StopEvent] = []
        w = max(2, int(round(self.window_s * self.sample_rate)))
        for v in np.asarray(block, dtype=np.float64).ravel().tolist():
            i = self._n
            self._n += 1
            if self._anchor is None or abs(v - self._anchor) >= self.min_motion:
                if self._anchor is not None:
                    self._moved = True
                    self.latched = False
                self._anchor, self._anchor_i = v, i
                continue
            if self._moved and not self.latched and i - self._anchor_i >= w:
                self.latched = True
                out.append(
                    StopEvent(
                        detected_at_s=self._t0 + i / self.sample_rate,
                        onset_s=self._t0 + self._anchor_i / self.sample_rate,
                        level_db=0.0,
                    )
                )
        return out
