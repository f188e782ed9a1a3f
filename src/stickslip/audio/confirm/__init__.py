"""Confirmation: a fire is reported as an end stop only once it persisted (the third stage).

* :mod:`.persistence` the window after a fire and the rule it must meet
* :mod:`.evidence`    what is kept of the stream: the per-frame evidence, the latest samples
* :mod:`.pause`       a fire that persisted but was the stepping stopping: not an end stop
* :mod:`.resume`      after a pause: where the stepping comes back, from which the detector listens afresh
* :mod:`.clocked`     a fire whose change is off the step clock's lines (added sound): not an end stop
* :mod:`.onset`       whether the confirmed stop began at the fire's onset
* :mod:`.sync`        the step clock's verdict (opt-in)
* :mod:`.late`        the late path: stops the fast path never heard, found on the step clock (opt-in)
* :mod:`.detector`    :class:`ConfirmedStopDetector`, which holds them together
"""

from .detector import ConfirmedStopDetector, ConfirmParams, confirming
from .persistence import PERSISTENCE, PersistenceParams, check_confirm_s

#: the default confirmation window, s (``PersistenceParams.confirm_s``: the default of ``listen`` and ``traverse``)
CONFIRM_S = PERSISTENCE.confirm_s

__all__ = [
    "CONFIRM_S",
    "ConfirmParams",
    "ConfirmedStopDetector",
    "PersistenceParams",
    "check_confirm_s",
    "confirming",
]
