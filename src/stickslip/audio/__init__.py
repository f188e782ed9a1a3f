"""The audio limit switch: hear a joint reach its end stop.

* :mod:`.detector` streaming band-power detector and its :class:`Tuning`
* :mod:`.tuning`   choose band and threshold from a labelled recording
* :mod:`.sources`  WAV files in blocks, a live microphone
"""

from __future__ import annotations

from .detector import StopDetector, StopEvent, Tuning, TuningFileError, detect
from .sources import AudioSourceError, Microphone, read_wav, wav_blocks, write_wav
from .tuning import TuningError, tune

__all__ = [
    "AudioSourceError",
    "Microphone",
    "StopDetector",
    "StopEvent",
    "Tuning",
    "TuningError",
    "TuningFileError",
    "detect",
    "read_wav",
    "tune",
    "wav_blocks",
    "write_wav",
]
