"""Motion: how many steps a move takes, and where the joints are after it.

* :mod:`.planning` — steps for a joint move in a pose, dead reckoning (``Planner``).
* :mod:`.reach` — straight tip lines in task space cut into segments of signed steps.
* :mod:`.tracking` — a Kalman filter over each joint's position and step scale, fed by
  sparse observations (a microscope reading, an end stop).

The main names are importable from here (``from stickslip.motion import Planner``).
"""

from .planning import MovePlan, Planner, dead_reckon, plan_move
from .reach import JointStepper, ReachPlan, ReachSegment, borrow_joint1, plan_reach
from .tracking import JointTrack, PositionTracker, scaled_calibration, track_for

__all__ = [
    "MovePlan",
    "Planner",
    "dead_reckon",
    "plan_move",
    "JointStepper",
    "ReachPlan",
    "ReachSegment",
    "borrow_joint1",
    "plan_reach",
    "JointTrack",
    "PositionTracker",
    "scaled_calibration",
    "track_for",
]
