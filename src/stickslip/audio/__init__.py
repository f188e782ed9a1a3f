"""The audio limit switch: hear a joint reach its end stop.

The detector is a chain of stages, each a package with one job (docs/audio.md):

* :mod:`.sources`     files, a microphone, a vibration stream; the dead-input guard
* :mod:`.features`    per-frame sub-band levels; the step clock (rate, harmonic lines)
* :mod:`.change`      the change detector: the stepping template, the fit to the stop's
  signature, the drops, the masking (the fast path: every fire)
* :mod:`.confirm`     a fire confirmed by its persistence; a pause is not a stop; when the
  stop began; the step clock and the late path (opt-in)
* :mod:`.tuning`      learn a joint's stop from a labelled recording, and check it
* :mod:`.comparators` the version-1 band-power detector, kept for old files and comparison

:mod:`.events` is the seam they share (:class:`StopEvent`, the :class:`StopDetector`
protocol); :mod:`.tuningfile` the tuning and its file; :mod:`.detector` assembles the
stages (:func:`detect`, :func:`detector_for`); :mod:`.parameters` lists every stage's
parameters.
"""

from __future__ import annotations

from .detector import detect, detector_for
from .events import StopDetector, StopEvent
from .sources import AudioSourceError, Microphone, read_wav, wav_blocks, write_wav
from .tuning import TuningError, tune
from .tuningfile import Tuning, TuningFileError

__all__ = [
    "AudioSourceError",
    "Microphone",
    "StopDetector",
    "StopEvent",
    "Tuning",
    "TuningError",
    "TuningFileError",
    "detect",
    "detector_for",
    "read_wav",
    "tune",
    "wav_blocks",
    "write_wav",
]
