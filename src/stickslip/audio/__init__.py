"""The audio limit switch: hear a joint reach its end stop.

* :mod:`.detector` streaming band-power detector and its :class:`Tuning`
* :mod:`.tuning`   learn the stepping template and the stop's signature from a labelled recording
  (:mod:`.labels`, :mod:`.verification`; :mod:`.band_tuning` for version-1 tunings)
* :mod:`.template` the spectral-template change detector; :mod:`.meter` the record meter
* :mod:`.sources`  WAV files in blocks, a live microphone
* :mod:`.confirm`  a fire confirmed by its persistence; :mod:`.stepclock` the step rate and the
  step-synchronous power heard in the sound (the step clock, an opt-in condition of confirmation)
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
