"""Calibrating the step-size models from traverses (the paper's Section 3.3, 3.5).

Three ways in, one result object (:class:`Calibration`):

* **paper** — the paper's procedure. Prismatic joint: six traverses at
  ``(q2, theta, psi) = (-pi/2, 0, 0), (0, -pi/2, 0), (0, 0, 0)``, Eqs. (4)–(6), in any
  order. Rotary joint: eight full-range traverses at ``(q3, theta, psi) = (0, 0, 0),
  (12 mm, 0, 0), (12 mm, -pi/2, 0), (0, -pi/2, 0)``; the unloaded ones give
  ``gamma0`` directly, and ``d`` is found by *inverting the exact relation*
  ``gamma_measured = range / integral dq / (gamma0 + d L(q))`` with a bracketed root
  find (:func:`invert_d_exact`), where the paper fitted a quadratic to simulations.
* **paper-quadratic** — the paper's own Eq. 9 method, kept as a comparator
  (:func:`fit_paper_quadratic`): simulate many ``(gamma0, d)``, fit
  ``d = p2 D^2 + p1 D + p0`` with ``D = gamma(theta=0) - gamma0``, invert with it.
  Eq. 9 *as printed* (:data:`EQ9_PRINTED`, :func:`eq9_printed`) cannot be right: for the
  ``|D| <= 9.2 µrad`` the paper quotes it gives ``d < 1 µrad``, while Fig. 10 reports
  ``d`` up to 24 µrad; the exact relation gives ``d ≈ 2.4 D`` for small ``D``.
* **lsq** — nonlinear least squares on any set of traverses
  (``scipy.optimize.least_squares``), with standard errors, refusing with a clear
  message when the poses cannot determine a parameter.

All values SI: prismatic steps in m, rotary steps in rad.
"""

from __future__ import annotations

from .auto import calibrate
from .inversion import EQ9_PRINTED, PaperQuadratic, eq9_printed, fit_paper_quadratic, invert_d_exact
from .lsq import calibrate_lsq
from .paper import PRISMATIC_PAPER_POSES, ROTARY_PAPER_POSES, calibrate_paper, paper_applicable
from .result import (
    FORMAT,
    FORMAT_VERSION,
    UNITS,
    Calibration,
    CalibrationError,
    Conditions,
    Parameter,
    Provenance,
    table_digests,
)
from .validation import ValidationResult, validate

__all__ = [
    "CalibrationError",
    "Calibration",
    "Conditions",
    "Parameter",
    "Provenance",
    "table_digests",
    "calibrate",
    "calibrate_paper",
    "calibrate_lsq",
    "invert_d_exact",
    "PaperQuadratic",
    "fit_paper_quadratic",
    "EQ9_PRINTED",
    "eq9_printed",
    "ValidationResult",
    "validate",
    "PRISMATIC_PAPER_POSES",
    "ROTARY_PAPER_POSES",
    "FORMAT",
    "FORMAT_VERSION",
    "UNITS",
    "paper_applicable",
]

