"""A Cartesian arm: three prismatic stages along fixed axes carrying a tool (a rig file's ``xyz`` arm).

The holder is at ``sum_i q_i a_i`` (``a_i`` the unit direction of stage ``i`` in the
arm's base frame, ``q_i`` its coordinate, m) and the tip at ``holder + tool``, so

    p(q) = A^T q + tool,    A = [a_1; a_2; a_3] (one axis a row)

is linear: the Jacobian is ``A^T`` everywhere, a straight tip line is a straight line
in joint space, and the inverse is ``q = A^-T (p - tool)``. There is no singular pose
(the axes are independent: a rig file refuses three in one plane).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Stage"]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Stage:
    """The tip of three prismatic stages: ``axes`` (unit vectors, base frame) and ``tool`` (m, base frame)."""

    axes: tuple[Vec3, Vec3, Vec3] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    tool: Vec3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        a = np.asarray(self.axes, dtype=float)
        if a.shape != (3, 3) or not np.all(np.isfinite(a)) or abs(float(np.linalg.det(a))) < 1e-9:
            raise ValueError("a stage's 3 axes must be finite and not in one plane")

    def matrix(self) -> NDArray[np.float64]:
        """``A``: one axis a row."""
        return np.asarray(self.axes, dtype=float)

    def tip(self, q: ArrayLike) -> NDArray[np.float64]:
        """The tip at joints ``q`` ``(..., 3)`` (m), base frame, m: ``A^T q + tool``."""
        return np.asarray(np.asarray(q, dtype=float) @ self.matrix() + np.asarray(self.tool), dtype=float)

    def inverse(self, p: ArrayLike) -> NDArray[np.float64]:
        """The joints (m) that put the tip at ``p`` (m, base frame): ``A^-T (p - tool)``."""
        r = np.asarray(p, dtype=float) - np.asarray(self.tool)
        return np.asarray(np.linalg.solve(self.matrix().T, r.T).T, dtype=float)

    def joint_rates(self, v: ArrayLike) -> NDArray[np.float64]:
        """Joint velocities (m/s) for a tip velocity ``v`` (m/s, base frame): ``A^-T v`` (the same in every pose)."""
        return np.asarray(np.linalg.solve(self.matrix().T, np.asarray(v, dtype=float)), dtype=float)
