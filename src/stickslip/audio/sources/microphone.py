"""A live microphone through python-sounddevice (PortAudio), imported lazily.

The simulator's virtual microphone lives with the simulator (:mod:`stickslip.sim.arm`);
a serial vibration sensor in :mod:`.vibration`. All yield blocks of mono samples.
"""

from __future__ import annotations

import queue
from collections.abc import Iterator
from typing import Any

import numpy as np

from .files import AUDIO_EXTRA, AudioSourceError

__all__ = ["Microphone"]


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
            raise AudioSourceError(f"live input needs python-sounddevice; {AUDIO_EXTRA}") from e
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
