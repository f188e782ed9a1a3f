"""A simulated measurement table with known truth, for the analysis and report tests."""

from __future__ import annotations

import math

import numpy as np

from stickslip.measurements import Traverse
from stickslip.models import JointModel, PrismaticParams, RotaryParams

__all__ = ["L3", "TRUE_PRISMATIC", "TRUE_ROTARY", "simulated_table"]

L3 = 0.012
"""The prismatic stroke, m."""

TRUE_PRISMATIC = {"+": PrismaticParams(972e-9, 0.27, 372e-9), "-": PrismaticParams(899e-9, 0.25, -436e-9)}
"""The paper's published prismatic values (its Fig. 4b caption), SI."""
TRUE_ROTARY = {
    "-": RotaryParams((45e-6, 50e-6), (3.83e-6, 23.94e-6)),
    "+": RotaryParams((42e-6, 47e-6), (-8.15e-6, -19.4e-6)),
}
"""d from the paper's Fig. 10 (q3 = 0 and 12 mm); gamma0 of the size its Fig. 6 shows."""


def simulated_table(seed: int, noise: float = 0.02, day: str = "2026-11-22") -> list[Traverse]:
    """Rows from the true models with multiplicative noise: gamma_row = gamma_model (1 + noise N(0, 1)).

    Joint 3: q2 in {0, -30, ..., -180} deg x theta in {0, -60, -90} deg, psi = 0 (the paper's
    experiment 1). Joint 2: full range at q3 in {0, 12 mm} x theta in {0, -90} deg, and the
    eight pi/6 intervals at theta = 0 for both q3 (the paper's Fig. 6 data).
    """
    rng = np.random.default_rng(seed)
    rows = []
    for d in ("+", "-"):
        m3, m2 = JointModel(3, d, TRUE_PRISMATIC[d]), JointModel(2, d, TRUE_ROTARY[d])
        s3, e3 = (0.0, L3) if d == "+" else (L3, 0.0)
        for q2 in np.arange(7) * -math.pi / 6:
            for th in (0.0, -math.pi / 3, -math.pi / 2):
                g = float(m3.average_gamma(s3, e3, 0.0, q2, 0.0, th, 0.0)) * (1 + noise * rng.standard_normal())
                rows.append(Traverse(day, 3, d, 0.0, float(q2), 0.0, th, 0.0, s3, e3, round(L3 / g)))
        edges = np.linspace(-7 * math.pi / 6, math.pi / 6, 9)
        spans = [(edges[0], edges[-1], th) for th in (0.0, -math.pi / 2)] + [
            (lo, hi, 0.0) for lo, hi in zip(edges[:-1], edges[1:], strict=True)
        ]
        for q3 in (0.0, 0.012):
            for lo, hi, th in spans:
                s, e = (float(lo), float(hi)) if d == "+" else (float(hi), float(lo))
                g = float(m2.average_gamma(s, e, 0.0, 0.0, q3, th, 0.0)) * (1 + noise * rng.standard_normal())
                rows.append(Traverse(day, 2, d, 0.0, 0.0, q3, th, 0.0, s, e, round(abs(e - s) / g)))
    return rows
