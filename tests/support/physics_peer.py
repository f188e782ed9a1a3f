"""An independent stick-slip cell: event-driven integration with scipy's solve_ivp.

The library's cell (:func:`stickslip.sim.physics.simulate_cell`) steps a fixed grid with
semi-implicit Euler and locates stick/slip switches by interpolation inside a step. This
peer integrates each phase (stick or slip) with an adaptive Runge-Kutta method and ends a
phase at the exact event (the force needed to stick exceeds static friction; the relative
velocity crosses zero), so the two share only the physics, not the numerics.
Mount compliance is left out here (``mount`` is compared at a stiff mount only).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

Vec = NDArray[np.float64]


def _terminal(event: Callable[[float, Vec], float], direction: float) -> Callable[[float, Vec], float]:
    """``event`` marked as solve_ivp wants it: integration ends where it crosses zero in ``direction``."""
    event.terminal = True  # type: ignore[attr-defined]  # solve_ivp reads these two attributes of the event
    event.direction = direction  # type: ignore[attr-defined]
    return event


def peer_step(u: float, n: float, kappa: float, t_fall: float = 0.01, tau_p: float = 0.01, zeta_p: float = 0.25,
              mu_ratio: float = 0.7, v_s: float = 2.0, sigma: float = 0.02) -> float:
    """Slider travel over the second drive period (strokes), rigid mount."""
    w = 2.0 * math.pi / tau_p
    rise = 1.0 - t_fall

    def volt(t: float) -> float:
        tt = t % 1.0
        return tt / rise if tt < rise else 1.0 - (tt - rise) / t_fall

    def piezo(t: float, e: float, ed: float) -> float:
        return w * w * (volt(t) - e) - 2.0 * zeta_p * w * ed

    def friction(vr: float) -> float:
        return -math.copysign(1.0, vr) * (n * mu_ratio + (n - n * mu_ratio) * math.exp(-((vr / v_s) ** 2))) - sigma * vr

    # state: e, ed, xs, vs ; stick: vs = ed, xs moves with ed
    t, e, ed, xs, vs = 0.0, 0.0, 0.0, 0.0, 0.0
    stick = True
    marks = {}
    breaks = [rise, 1.0, 1.0 + rise, 2.0]
    while t < 2.0 - 1e-12:
        t_end = min(b for b in breaks if b > t + 1e-12)
        if stick:
            def rhs_stick(tt: float, y: Vec) -> list[float]:
                a = piezo(tt, y[0], y[1])
                return [y[1], a, y[1]]

            def ev_slip(tt: float, y: Vec) -> float:
                a = piezo(tt, y[0], y[1])
                return n - abs(kappa * a - u)

            sol = solve_ivp(rhs_stick, (t, t_end), [e, ed, xs], events=_terminal(ev_slip, -1.0), rtol=1e-6, atol=1e-9,
                            max_step=tau_p / 6)
            e, ed, xs = sol.y[:, -1]
            vs = ed
            t = sol.t[-1]
            if sol.status == 1:
                stick = False
        else:
            vr0 = vs - ed
            sgn0 = math.copysign(1.0, vr0) if vr0 != 0 else -math.copysign(1.0, kappa * piezo(t, e, ed) - u)

            def rhs_slip(tt: float, y: Vec, sgn0: float = sgn0) -> list[float]:
                a = piezo(tt, y[0], y[1])
                vr = y[3] - y[1]
                fr = friction(vr) if vr != 0 else -sgn0 * n
                return [y[1], a, y[3], (fr + u) / kappa]

            def ev_stick(tt: float, y: Vec) -> float:
                return float(y[3] - y[1])

            sol = solve_ivp(rhs_slip, (t, t_end), [e, ed, xs, vs], events=_terminal(ev_stick, -sgn0), rtol=1e-6,
                            atol=1e-9, max_step=tau_p / 6, first_step=1e-7)
            e, ed, xs, vs = sol.y[:, -1]
            t = sol.t[-1]
            if sol.status == 1:
                a = piezo(t, e, ed)
                if abs(kappa * a - u) <= n:
                    stick = True
                    vs = ed
                else:
                    vs = ed + 1e-9 * (-sgn0)  # slips on the other way
        for b in (1.0, 2.0):
            if b not in marks and t >= b - 1e-12:
                marks[b] = xs
    return float(marks[2.0] - marks[1.0])


if __name__ == "__main__":  # pragma: no cover
    for u in (-0.2, 0.0, 0.2):
        print(u, peer_step(u, 1.0, 1e-3))
