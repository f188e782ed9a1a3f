"""What the bluesky tests share: the day the simulator runs on and its true models as a calibration.

The RunEngine fixture ``RE`` is in ``conftest.py``.
"""

from __future__ import annotations

from stickslip.calibration import Calibration
from stickslip.sim.arm import SimulatedMM3A

DAY = "2026-11-22"


def true_calibration(sim: SimulatedMM3A) -> Calibration:
    """The simulator's own models as a calibration (exact by construction)."""
    models = sim.true_models()
    return Calibration(
        models=models, stderr=dict.fromkeys(models), constant_steps=dict.fromkeys(models, 1e-6), day=DAY, method="paper"
    )
