"""Features of the sound, frame by frame and stretch by stretch: the detector's second stage.

* :mod:`.spectra`   per-frame band and sub-band levels, and the continuum between the step clock's lines
* :mod:`.frames`    a stream cut into frames (the samples kept for the judgements that look back)
* :mod:`.stepclock` the step rate heard, the power on its harmonic lines and how it changed
* :mod:`.lockin`    the steps' clock followed from the sound, and the lines' power in phase with it
* :mod:`.fine`      the fine continuum spectrum a tuning keeps, and the stop's signature predicted from it
  at another step rate
"""
