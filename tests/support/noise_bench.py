"""The noise bench's recording (``benchmarks/bench_audio_stops_noise.py``): the tenth generator's arm stepping into
its stop with a source of the hour's (speech, music, a radio) added over the whole recording."""

from __future__ import annotations

import numpy as np
from fan_sound import SR, Arm, Scene, render
from hour_sound import over_stepping

#: the stop, s into the recording
STOP_S = 12.0


def recording(arm: int, rate_hz: float, kind: str, level_db: float) -> np.ndarray:
    """Arm ``arm`` stepping at ``rate_hz`` into its stop at :data:`STOP_S` (2 s more after it), ``kind`` added at
    ``level_db`` to the stepping's RMS before the stop (float32 samples at :data:`fan_sound.SR`)."""
    y = render(Scene(Arm(arm), rate=rate_hz, stop_at=STOP_S, dur=STOP_S + 2.0, seed=int(rate_hz) + arm + 77))
    rng = np.random.default_rng(arm * 100 + int(rate_hz) + int(level_db))
    return np.asarray(over_stepping(y, kind, level_db, rng, int(STOP_S * SR)), dtype=np.float32)
