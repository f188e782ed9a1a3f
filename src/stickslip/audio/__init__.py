"""The audio limit switch: hear a joint reach its end stop.

* :mod:`.synth`    what the room hears (the simulator's virtual microphone)
* :mod:`.detector` streaming band-power detector and its :class:`Tuning`
* :mod:`.tuning`   choose band and threshold from a labelled recording
* :mod:`.sources`  WAV files in blocks, a live microphone
"""

from __future__ import annotations
