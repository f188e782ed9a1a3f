"""Figures in the manner of the paper's, and a self-contained HTML report.

Compute, then plot: each ``*_data`` function returns a small result object holding
arrays in SI units; its ``.plot(ax=None)`` draws it with labelled display units (nm,
µrad, degrees) and returns the Axes. matplotlib is imported lazily, with the Agg
backend when there is no display; figures are returned, never shown.

* :func:`prismatic_data` -- Fig. 4: step of joint 3 against ``zeta = psi - q2``, a
  model line per tilt in the data, measured points, one panel per day and direction.
* :func:`rotary_interval_data` -- Figs. 6 and 10: average step of a rotary joint over
  each traversed interval against ``zeta`` at its midpoint, beside the model's exact
  average over the same interval; one panel per day and direction.
* :func:`step_simulation_data` -- Fig. 8: the calibrated joint 2 simulated step by step
  (:func:`stickslip.models.iter_traverse_steps`).
* :func:`d_relation_data` -- Fig. 9: ``d`` against ``D = gamma(theta=0) - gamma0``.
* :func:`validation_data` -- relative errors of the model and the constant step, per
  day and joint, labelled in-sample or out-of-sample (:func:`classify_sample`).
* :func:`build_report` -- all of the above as PNGs plus ``index.html``.

Modules: ``panels`` (the per-day figure object), ``prismatic``, ``rotary``, ``steps``,
``d_relation``, ``validation``, ``sample``, ``html`` (the page, no plotting), ``build``.
"""

from __future__ import annotations

from .build import Report, build_report
from .d_relation import PAPER_DELTA_RANGE, CalibratedPoint, DRelation, d_relation_data
from .panels import MODEL_ONLY, Curve, Panel, StepFigure
from .prismatic import prismatic_data
from .rotary import pi6_intervals, rotary_interval_data
from .sample import Sample, classify_days, classify_sample, table_sha256
from .steps import StepRun, StepSimulation, step_simulation_data
from .validation import ValidationCell, ValidationFigure, validation_data

__all__ = [
    "MODEL_ONLY",
    "PAPER_DELTA_RANGE",
    "CalibratedPoint",
    "Curve",
    "DRelation",
    "Panel",
    "Report",
    "Sample",
    "StepFigure",
    "StepRun",
    "StepSimulation",
    "ValidationCell",
    "ValidationFigure",
    "build_report",
    "classify_days",
    "classify_sample",
    "d_relation_data",
    "pi6_intervals",
    "prismatic_data",
    "rotary_interval_data",
    "step_simulation_data",
    "table_sha256",
    "validation_data",
]
