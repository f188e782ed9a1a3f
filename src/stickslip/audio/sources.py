"""Where the detector's audio comes from: WAV files in blocks, or a live microphone.

The simulator's virtual microphone lives with the simulator
(:mod:`stickslip.sim.arm`); it yields blocks the same way.
Both sources here import their optional dependency lazily and say which extra to
install when it is missing.
"""

from __future__ import annotations

import math
import queue
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..records import atomic_write, regular_file

__all__ = [
    "CANCEL_DB",
    "DROWNED_DB",
    "WEAK_LINE_DB",
    "AudioSourceError",
    "Microphone",
    "channel_problem",
    "read_wav",
    "wav_blocks",
    "wav_info",
    "write_wav",
]

_AUDIO_EXTRA = "install the audio extra: pip install 'stickslip[audio]'"


class AudioSourceError(OSError):
    """An audio source that cannot be opened or read (the message says why)."""


def _soundfile() -> Any:
    try:
        import soundfile
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise AudioSourceError(f"reading WAV files needs soundfile; {_AUDIO_EXTRA}") from e
    except OSError as e:  # pragma: no cover - libsndfile missing
        raise AudioSourceError(f"soundfile cannot load libsndfile ({e}); apt-get install libsndfile1") from e
    return soundfile


def _regular(path: str | Path) -> Path:
    """``path`` if it is a regular file: a FIFO or device is never opened (records.regular_file), else the reason."""
    p = Path(path)
    if not p.exists():
        return p  # said where it is opened, as before
    try:
        return regular_file(p, "recording")
    except ValueError as e:
        raise AudioSourceError(str(e)) from None


def _open_error(path: Path, e: Exception) -> AudioSourceError:
    if not path.exists():
        return AudioSourceError(f"{path}: no such file")
    if path.is_dir():
        return AudioSourceError(f"{path}: is a directory, not a WAV file")
    return AudioSourceError(f"{path}: not a readable audio file ({e})")


def wav_info(path: str | Path) -> tuple[int, int, float]:
    """(sample rate Hz, channels, duration s) of an audio file."""
    sf = _soundfile()
    p = _regular(path)
    try:
        info = sf.info(str(p))
    except Exception as e:  # soundfile raises LibsndfileError / RuntimeError / TypeError
        raise _open_error(p, e) from None
    return int(info.samplerate), int(info.channels), float(info.frames) / info.samplerate


def _check_channel(p: Path, channel: int | None, channels: int) -> None:
    if channel is not None and not 0 <= int(channel) < channels:
        have = "1 channel" if channels == 1 else f"{channels} channels (1 to {channels})"
        raise AudioSourceError(f"{p} has {have}: there is no channel {int(channel) + 1}")


def wav_blocks(path: str | Path, block: int = 1024, channel: int | None = None) -> Iterator[tuple[np.ndarray, int]]:
    """Read an audio file in blocks: yields ``(mono float32 samples, sample rate Hz)``.

    Multi-channel files are mixed down to mono (mean of the channels), or ``channel``
    (0-based: 0 is the first, left) is read alone (see :func:`channel_problem` for when
    the mean loses the stepping sound). The last block may be shorter.
    """
    if int(block) < 1:
        raise ValueError(f"block must be >= 1 sample, got {block}")
    sf = _soundfile()
    p = _regular(path)
    try:
        f = sf.SoundFile(str(p))
    except Exception as e:
        raise _open_error(p, e) from None
    with f:
        rate = int(f.samplerate)
        _check_channel(p, channel, int(f.channels))
        for data in f.blocks(blocksize=int(block), dtype="float32", always_2d=True):
            if channel is not None:
                yield data[:, int(channel)].copy(), rate
            else:
                yield data.mean(axis=1, dtype=np.float32) if data.shape[1] > 1 else data[:, 0], rate


def read_wav(path: str | Path, channel: int | None = None) -> tuple[np.ndarray, int]:
    """A whole audio file as ``(mono float32 samples, sample rate Hz)`` (``channel``: see :func:`wav_blocks`)."""
    rate = wav_info(path)[0]
    blocks = [b for b, _ in wav_blocks(path, block=1 << 16, channel=channel)]
    return (np.concatenate(blocks) if blocks else np.zeros(0, np.float32)), rate


#: the mean of a file's channels this far (dB) below its loudest channel: they cancel (opposite polarity)
CANCEL_DB = -12.0
#: a step-rate line this many dB clearer in one channel than in the mean ...
DROWNED_DB = 6.0
#: ... where the mean's stands less than this clear, dB: the mean blurs the steps (another channel's noise drowns
#: them; or two microphones about half a step period apart in their envelopes: each click heard twice, 0.44 ms
#: apart, the mean's line at 1000 Hz falls from 40 to 9-14 dB and its envelope reads 2000 Hz; at other delays it
#: falls by 11 dB or less, still clear)
WEAK_LINE_DB = 15.0


def channel_problem(path: str | Path, seconds: float = 2.0) -> str | None:
    """Why the mean of a multi-channel file's channels would lose the stepping sound, or ``None``.

    Judged on the first ``seconds`` of the file, two ways:

    * *cancellation*: the mean's RMS is :data:`CANCEL_DB` or more below the loudest
      channel's: the channels carry the same sound in opposite polarity (a balanced
      microphone wired to both inputs of a stereo card) and their mean is near silence;
    * *drowned*: in some channel the step-rate line of the envelope
      (:func:`~stickslip.audio.guard.step_line_db`, at the rate heard there:
      :func:`~stickslip.audio.stepclock.step_rate_hz`) stands at least the no-signal
      guard's 8 dB clear (``SignalGuard.min_line_db``), and
      :data:`DROWNED_DB` or more clearer than in the mean, whose line stands less than
      :data:`WEAK_LINE_DB` clear: another channel (an open input picking up hum or noise)
      drowns it, or the channels hear each click at times far enough apart that their
      mean's envelope no longer beats at the step rate (two microphones some 15 cm apart).

    The message names the channel to read instead (1-based, as ``--channel`` takes it).
    ``None`` for a mono file, a file too short to judge, or a mean that keeps the stepping.
    """
    from .guard import SignalGuard, step_line_db
    from .stepclock import step_rate_hz

    sf = _soundfile()
    p = _regular(path)
    try:
        with sf.SoundFile(str(p)) as f:
            rate, n = int(f.samplerate), int(f.channels)
            if n < 2:
                return None
            data = f.read(frames=int(seconds * rate), dtype="float64", always_2d=True)
    except Exception as e:
        raise _open_error(p, e) from None
    data = np.nan_to_num(data, nan=0.0, posinf=1.0, neginf=-1.0)
    if data.shape[0] == 0:
        return None
    mix = data.mean(axis=1)
    rms = np.sqrt(np.mean(data**2, axis=0))
    mix_rms = float(np.sqrt(np.mean(mix**2)))
    loud = int(np.argmax(rms))
    if rms[loud] <= 0.0:
        return None
    mix_db = 20.0 * np.log10(max(mix_rms, 1e-300) / float(rms[loud]))
    if mix_db <= CANCEL_DB:
        return (
            f"{p}: the mean of its {n} channels is {max(mix_db, -200.0):.0f} dB below channel {loud + 1}: they carry "
            f"the sound in opposite polarity and cancel; read one channel with --channel {loud + 1}"
        )
    # a noise floor 80 dB under each channel: a synthetic pure tone's envelope has no noise between its lines, and
    # any bin there would stand "clear" of a median that is only rounding error
    dither = 1e-4 * np.random.default_rng(0).standard_normal(data.shape)
    data = data + dither * rms
    mix = mix + dither[:, 0] * mix_rms
    lines = []
    for c in range(n):
        r = step_rate_hz(data[:, c], rate)
        line = step_line_db(data[:, c], rate, r) if math.isfinite(r) else -math.inf
        lines.append((line if math.isfinite(line) else -math.inf, r))
    best = max(range(n), key=lambda c: lines[c][0])
    line, r = lines[best]
    if line < SignalGuard.min_line_db:  # no channel shows stepping as the guard asks for it
        return None
    in_mix = step_line_db(mix, rate, r)
    if math.isfinite(in_mix) and in_mix < WEAK_LINE_DB and line - in_mix >= DROWNED_DB:
        return (
            f"{p}: the step rate's line ({r:.0f} Hz) stands {line:.0f} dB clear in channel {best + 1} but "
            f"{in_mix:.0f} dB in the mean of the {n} channels: the mean blurs the steps (noise on another channel, or "
            f"microphones that hear each step at other times); read "
            f"channel {best + 1} alone with --channel {best + 1}"
        )
    return None


def write_wav(path: str | Path, samples: np.ndarray, sample_rate: int) -> Path:
    """Write mono samples as a 32-bit float WAV file.

    The write goes through a temporary file in the same folder: a write that fails (a
    full disk, a folder that is not there or not writable) leaves an earlier file at
    ``path`` as it was, and raises ``OSError``.
    """
    sf = _soundfile()
    p = Path(path)
    data = np.asarray(samples, dtype=np.float32)

    def write(f: Any) -> None:
        try:
            sf.write(f, data, int(sample_rate), subtype="FLOAT", format="WAV")
        except (RuntimeError, ValueError, TypeError) as e:  # libsndfile's errors are RuntimeErrors
            raise OSError(f"cannot write a WAV file: {e}") from None

    return atomic_write(p, write, mode="wb")


class Microphone:
    """A live microphone through python-sounddevice (PortAudio).

    The stream's callback only copies each block into a queue; :meth:`blocks` hands
    them out in the caller's thread, so detection never runs inside the audio callback.

    Parameters
    ----------
    sample_rate : int
        Sample rate, Hz.
    block : int
        Samples per block.
    device : int or str, optional
        PortAudio input device (index or name); default the system's input.
    channels : int
        Channels to record; they are mixed to mono.

    Raises
    ------
    AudioSourceError
        When sounddevice or PortAudio is missing, or no input device can be opened.

    Examples
    --------
    >>> with Microphone() as mic:                      # doctest: +SKIP
    ...     for block in mic.blocks():
    ...         events = detector.feed(block)
    """

    def __init__(
        self,
        sample_rate: int = 48_000,
        block: int = 1024,
        device: int | str | None = None,
        channels: int = 1,
    ) -> None:
        self.sample_rate = int(sample_rate)
        self.block = int(block)
        self.device = device
        self.channels = int(channels)
        self.overflows = 0
        self._queue: queue.Queue[np.ndarray] = queue.Queue()
        self._stream: Any = None

    @staticmethod
    def _sounddevice() -> Any:
        try:
            import sounddevice
        except ImportError as e:
            raise AudioSourceError(f"live input needs python-sounddevice; {_AUDIO_EXTRA}") from e
        except OSError as e:  # sounddevice raises OSError when PortAudio is absent
            raise AudioSourceError(f"PortAudio is not installed ({e}); apt-get install libportaudio2") from e
        return sounddevice

    def _callback(self, indata: np.ndarray, frames: int, time_info: Any, status: Any) -> None:  # PortAudio's thread
        if status and getattr(status, "input_overflow", False):
            self.overflows += 1
        self._queue.put(indata.copy())

    def start(self) -> Microphone:
        """Open and start the input stream."""
        sd = self._sounddevice()
        try:
            self._stream = sd.InputStream(
                samplerate=self.sample_rate,
                blocksize=self.block,
                device=self.device,
                channels=self.channels,
                dtype="float32",
                callback=self._callback,
            )
            self._stream.start()
        except Exception as e:  # PortAudioError, ValueError for a bad device
            self._stream = None
            raise AudioSourceError(
                f"cannot open the microphone: {e} (is an input device connected? "
                "'python -m sounddevice' lists them; choose one with --input)"
            ) from None
        return self

    def stop(self) -> None:
        """Stop and close the stream (safe to call twice)."""
        if self._stream is not None:
            try:
                self._stream.stop()
                self._stream.close()
            finally:
                self._stream = None

    def __enter__(self) -> Microphone:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def blocks(self, timeout_s: float = 2.0) -> Iterator[np.ndarray]:
        """Yield mono float32 blocks as they arrive; raises if none comes for ``timeout_s``."""
        if self._stream is None:
            self.start()
        while True:
            try:
                data = self._queue.get(timeout=timeout_s)
            except queue.Empty:
                raise AudioSourceError(f"no audio from the microphone for {timeout_s:g} s") from None
            yield data.mean(axis=1) if data.ndim == 2 and data.shape[1] > 1 else data.reshape(-1)
