"""stickslip: load-aware step sizes for piezoelectric stick-slip micromanipulators.

Measure a joint's average step size by counting steps between end stops, model how
static load and pose change it (Damani, Nambi & Abbott's Eqs. 2-9), calibrate the
model from a handful of traverses, and plan moves in any pose. SI units throughout.
"""

import logging as _logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover - the names below are imported on first use
    from .kinematics import JOINTS, gravity_base, load_term, zeta
    from .measurements import Traverse, read_measurements, write_measurements
    from .models import JointModel, PrismaticParams, RotaryParams, eta, gamma_prismatic, gamma_rotary

# The public names load their module (and numpy) on first use, so that the command line
# starts without numpy when a command does not need it (``stickslip --help``).
_LAZY = {
    "JOINTS": "kinematics",
    "gravity_base": "kinematics",
    "load_term": "kinematics",
    "zeta": "kinematics",
    "Traverse": "measurements",
    "read_measurements": "measurements",
    "write_measurements": "measurements",
    "JointModel": "models",
    "PrismaticParams": "models",
    "RotaryParams": "models",
    "eta": "models",
    "gamma_prismatic": "models",
    "gamma_rotary": "models",
}


def __getattr__(name: str) -> object:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'stickslip' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__version__ = "0.1.0"

# A library logs, the application decides what to show: without this, Python's last-resort
# handler prints every warning (a stop that could not be sent, a NanoControl "i" answer)
# to stderr beside the command's own one-line error.
_logging.getLogger(__name__).addHandler(_logging.NullHandler())

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
