"""The change detector: an end stop is a lasting departure from the stepping sound (the fast path).

* :mod:`.tuned`    what it takes from a tuning, in frames, and the fires it gives
* :mod:`.template` the running template of the stepping sound and its floor (the sound added to it)
* :mod:`.added`    sound there from the start: the joint's own level under the first template
* :mod:`.fit`      each frame fitted to the stop's signature: the stop-likeness and the residual
* :mod:`.rate`     the signatures fitted: the tuned one, the one predicted at the heard rate, masked
* :mod:`.drops`    the drops below the floor: in proportion to the rise, and the drop channel
* :mod:`.start`    whether listening began at the stop
* :mod:`.stale`    whether a fire was the template gone stale with a drifting rate
* :mod:`.release`  when a latched detector re-arms because the joint steps again
* :mod:`.state`    the frame loop that holds them together: hold, fire, latch
* :mod:`.detector` the stream: samples in, :class:`~stickslip.audio.events.StopEvent` s out
"""

from .detector import TemplateDetector
from .state import ChangeParams, ChangeState

__all__ = ["ChangeParams", "ChangeState", "TemplateDetector"]
