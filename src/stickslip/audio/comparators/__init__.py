"""Detectors kept beside the one ``tune`` makes: to compare with, and for the files that name them.

* :mod:`.band` the band-power detector of tuning files version 1 (:class:`.band.BandDetector`):
  the level of one band against a threshold. ``tune`` no longer makes such tunings
  (``tune_band`` still does, for comparison); a version-1 file still loads and is heard by it.
"""

from .band import BandDetector

__all__ = ["BandDetector"]
