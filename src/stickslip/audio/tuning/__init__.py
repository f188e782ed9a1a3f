"""Tuning and verification: learn how one joint's stop sounds from a labelled recording (the last stage).

* :mod:`.tune`         :func:`tune`: the spectral template (what ``stickslip tune`` makes)
* :mod:`.labels`       a labelled recording checked, and where its sound actually changes
* :mod:`.candidates`   the stepping band, the candidate templates, scored on their worst frames
* :mod:`.verification` the refusal that names what spoils them, and the self-check
* :mod:`.inject`       the self-check's interference: knocks, babble, a second click train
* :mod:`.params`       :class:`~.params.TuneParams`
* :mod:`.band`         :func:`tune_band`: the band-power tuner of version-1 files, kept for comparison
"""

from .band import candidate_bands, tune_band
from .candidates import stepping_band
from .labels import TuningError
from .params import TuneParams
from .tune import tune

__all__ = ["TuneParams", "TuningError", "candidate_bands", "stepping_band", "tune", "tune_band"]
