"""Audio files: read in blocks (mono, or one channel), written atomically.

soundfile (libsndfile) is imported lazily; a missing one is named with the extra to install.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ...records import atomic_write, regular_file

__all__ = [
    "AUDIO_EXTRA",
    "AudioSourceError",
    "open_error",
    "read_wav",
    "load_soundfile",
    "shortfall",
    "truncation",
    "wav_blocks",
    "wav_info",
    "write_wav",
]

AUDIO_EXTRA = "install the audio extra: pip install 'stickslip[audio]'"


class AudioSourceError(OSError):
    """An audio source that cannot be opened or read (the message says why)."""


def load_soundfile() -> Any:
    """The soundfile module, or :class:`AudioSourceError` saying what to install."""
    try:
        import soundfile
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise AudioSourceError(f"reading WAV files needs soundfile; {AUDIO_EXTRA}") from e
    except OSError as e:  # pragma: no cover - libsndfile missing
        raise AudioSourceError(f"soundfile cannot load libsndfile ({e}); apt-get install libsndfile1") from e
    return soundfile


def regular(path: str | Path) -> Path:
    """``path`` if it is a regular file: a FIFO or device is never opened (records.regular_file), else the reason."""
    p = Path(path)
    if not p.exists():
        return p  # said where it is opened, as before
    try:
        return regular_file(p, "recording")
    except ValueError as e:
        raise AudioSourceError(str(e)) from None


def open_error(path: Path, e: Exception) -> AudioSourceError:
    if not path.exists():
        return AudioSourceError(f"{path}: no such file")
    if path.is_dir():
        return AudioSourceError(f"{path}: is a directory, not a WAV file")
    return AudioSourceError(f"{path}: not a readable audio file ({e})")


def wav_info(path: str | Path) -> tuple[int, int, float]:
    """(sample rate Hz, channels, duration s) of an audio file."""
    sf = load_soundfile()
    p = regular(path)
    try:
        info = sf.info(str(p))
    except Exception as e:  # soundfile raises LibsndfileError / RuntimeError / TypeError
        raise open_error(p, e) from None
    return int(info.samplerate), int(info.channels), float(info.frames) / info.samplerate


def truncation(path: str | Path) -> str | None:
    """Why a WAV, RF64 or AIFF file holds less than its header says (a recorder stopped before closing it), or ``None``.

    libsndfile reads what a truncated file holds without a word: a recording cut short
    looked whole, its stop (if after the cut) never heard. The chunks are walked to the
    sound's (``data``; ``SSND`` in an AIFF), whose declared length (an RF64's in its ``ds64``
    chunk) is compared with the bytes after it; a length of 0 or 0xFFFFFFFF (what a
    streaming recorder writes before it knows) claims nothing. The lengths in seconds scale
    what libsndfile reads by the two byte counts. Other formats (FLAC, W64, ...) and a header
    that cannot be read say ``None``: read as before (an MP3: :func:`shortfall`).
    """
    try:
        with open(regular(path), "rb") as f:  # a FIFO or device is never opened: refused where the file is read
            sizes = _sound_bytes(f, f.seek(0, 2))
    except (OSError, struct.error, AudioSourceError):
        return None
    if sizes is None:
        return None
    declared, held = sizes
    if declared in (0, 0xFFFFFFFF) or declared <= held or held <= 0:
        return None
    try:
        held_s = wav_info(path)[2]
    except AudioSourceError:
        return None  # said where the file is read
    return (f"{path}: the header says {held_s * declared / held:.3f} s of sound but the file holds {held_s:.3f} s: "
            "it was cut short (a recorder that stopped before closing the file, a copy not finished); only what it "
            "holds is read")


def _sound_bytes(f: Any, size: int) -> tuple[int, int] | None:
    """(bytes the header declares, bytes the file holds) of the sound chunk of a RIFF/RF64/AIFF file, else None."""
    f.seek(0)
    head = f.read(12)
    little = head[:4] in (b"RIFF", b"RF64") and head[8:] == b"WAVE"
    if not little and not (head[:4] == b"FORM" and head[8:] in (b"AIFF", b"AIFC")):
        return None
    fmt, sound, pos, ds64 = ("<4sI", b"data", 12, None) if little else (">4sI", b"SSND", 12, None)
    while pos + 8 <= size:
        f.seek(pos)
        cid, n = struct.unpack(fmt, f.read(8))
        if cid == b"ds64" and n >= 16:
            ds64 = struct.unpack("<8xQ", f.read(16))[0]  # riff size, then the data chunk's 64-bit size
        elif cid == sound:
            declared = ds64 if (head[:4] == b"RF64" and n == 0xFFFFFFFF and ds64 is not None) else n
            skip = 0 if little else 8  # an SSND chunk opens with its offset and block size
            return max(declared - skip, 0), size - pos - 8 - skip
        pos += 8 + n + (n & 1)
    return None


def shortfall(path: str | Path, frames_read: int) -> str | None:
    """Why a file gave fewer frames than its header claims (an MP3 cut after its Xing header), or ``None``.

    The complement of :func:`truncation`, for the formats whose claimed length libsndfile
    reports as the header says it (for a WAV it reports what the file holds). A length it
    does not know (0, or the largest count) claims nothing.
    """
    try:
        info = load_soundfile().info(str(path))
    except Exception:  # noqa: BLE001  - read before: a file that cannot be opened now says nothing more
        return None
    claimed, rate = int(info.frames), float(info.samplerate)
    if not (0 < int(frames_read) < claimed < 2**62 and rate > 0):
        return None
    return (f"{path}: the header says {claimed / rate:.3f} s of sound but only {int(frames_read) / rate:.3f} s "
            "could be read: it was cut short (a recorder that stopped before closing the file, a copy not "
            "finished); only what it holds is read")


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
    sf = load_soundfile()
    p = regular(path)
    try:
        f = sf.SoundFile(str(p))
    except Exception as e:
        raise open_error(p, e) from None
    with f:
        rate = int(f.samplerate)
        _check_channel(p, channel, int(f.channels))
        # read until the decoder gives nothing, not SoundFile.blocks: that counts to the header's length and, for a
        # file that holds less (an MP3 cut after its Xing header), yields its buffer unfilled - the last block
        # again, or uninitialised memory (1.8e18), for the rest of the claimed length
        done = 0
        while True:
            try:
                data = f.read(int(block), dtype="float32", always_2d=True)
            except (RuntimeError, ValueError) as e:  # libsndfile's decoder errors (LibsndfileError) are RuntimeErrors
                cut = f"not readable past {done / rate:.3f} s"
                raise AudioSourceError(f"{p}: damaged or cut short: {cut} ({e})") from None
            if len(data) == 0:
                break
            done += len(data)
            if channel is not None:
                yield data[:, int(channel)].copy(), rate
            else:
                yield data.mean(axis=1, dtype=np.float32) if data.shape[1] > 1 else data[:, 0], rate


def read_wav(path: str | Path, channel: int | None = None) -> tuple[np.ndarray, int]:
    """A whole audio file as ``(mono float32 samples, sample rate Hz)`` (``channel``: see :func:`wav_blocks`)."""
    rate = wav_info(path)[0]
    blocks = [b for b, _ in wav_blocks(path, block=1 << 16, channel=channel)]
    return (np.concatenate(blocks) if blocks else np.zeros(0, np.float32)), rate


def write_wav(path: str | Path, samples: np.ndarray, sample_rate: int) -> Path:
    """Write mono samples as a 32-bit float WAV file.

    The write goes through a temporary file in the same folder: a write that fails (a
    full disk, a folder that is not there or not writable) leaves an earlier file at
    ``path`` as it was, and raises ``OSError`` (:class:`~stickslip.records.WriteError`).
    The WAV is made in memory first (as large as ``samples`` in float32): libsndfile
    writing into the file itself met a full disk inside its callbacks, where each failed
    write printed a traceback ("Exception ignored from cffi callback") before the error.
    """
    sf = load_soundfile()
    p = Path(path)
    data = np.asarray(samples, dtype=np.float32)
    wav = io.BytesIO()
    try:
        sf.write(wav, data, int(sample_rate), subtype="FLOAT", format="WAV")
    except (RuntimeError, ValueError, TypeError) as e:  # libsndfile's errors are RuntimeErrors
        raise OSError(f"cannot write a WAV file: {e}") from None
    return atomic_write(p, lambda f: f.write(wav.getbuffer()), mode="wb")
