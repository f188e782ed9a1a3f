"""Step-size models: the paper's forms and the families beyond them.

* :mod:`.paper` — the paper's Eqs. 2, 3, 7 and 8, the exact step integrals along a
  traverse and the step-by-step simulation (pure, vectorised functions, SI units).
* :mod:`.families` — model families beyond the paper's (docs/models.md §2, equations
  F1–F4), built on the same step profiles.

The paper's names are importable from here (``from stickslip.models import JointModel``);
the families from :mod:`stickslip.models.families`.
"""

from .paper import (
    DIRECTIONS,
    JointModel,
    NonPhysicalError,
    Params,
    PrismaticParams,
    RotaryParams,
    StepProfile,
    antiderivative_inverse_step,
    direction_label,
    direction_sign,
    eta,
    gamma_prismatic,
    gamma_rotary,
    interp_q3,
    iter_traverse_steps,
    position_after_steps,
    simulate_traverse_steps,
    sinusoid_range,
    steps_between,
    steps_between_quad,
)

__all__ = [
    "DIRECTIONS",
    "direction_sign",
    "direction_label",
    "eta",
    "gamma_prismatic",
    "gamma_rotary",
    "interp_q3",
    "PrismaticParams",
    "RotaryParams",
    "JointModel",
    "Params",
    "NonPhysicalError",
    "antiderivative_inverse_step",
    "StepProfile",
    "sinusoid_range",
    "steps_between",
    "steps_between_quad",
    "iter_traverse_steps",
    "simulate_traverse_steps",
    "position_after_steps",
]
