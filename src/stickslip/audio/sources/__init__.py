"""Where the detector's samples come from, and whether they are alive: the first stage.

* :mod:`.files`      audio files read in blocks (mono, or one channel), written atomically
* :mod:`.channels`   which channel of a multi-channel file carries the stepping
* :mod:`.microphone` a live microphone (PortAudio)
* :mod:`.vibration`  an accelerometer's stream: a CSV or WAV file, or a serial port
* :mod:`.guard`      the dead-input guard: silence, a constant, clipping, no stepping heard

The simulator's virtual microphone lives with the simulator (:mod:`stickslip.sim.arm`).
"""

from .channels import channel_problem
from .files import AudioSourceError, read_wav, shortfall, truncation, wav_blocks, wav_info, write_wav
from .microphone import Microphone

__all__ = [
    "AudioSourceError",
    "Microphone",
    "channel_problem",
    "read_wav",
    "shortfall",
    "truncation",
    "wav_blocks",
    "wav_info",
    "write_wav",
]
