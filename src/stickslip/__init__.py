"""stickslip: load-aware step sizes for piezoelectric stick-slip micromanipulators.

Measure a joint's average step size by counting steps between end stops, model how
static load and pose change it (Damani, Nambi & Abbott's Eqs. 2-9), calibrate the
model from a handful of traverses, and plan moves in any pose. SI units throughout.
"""

from .kinematics import JOINTS, gravity_base, load_term, zeta
from .measurements import Traverse, read_measurements, write_measurements
from .models import JointModel, PrismaticParams, RotaryParams, eta, gamma_prismatic, gamma_rotary

__version__ = "0.1.0"

__all__ = [
    "JOINTS",
    "JointModel",
    "PrismaticParams",
    "RotaryParams",
    "Traverse",
    "eta",
    "gamma_prismatic",
    "gamma_rotary",
    "gravity_base",
    "load_term",
    "read_measurements",
    "write_measurements",
    "zeta",
]
