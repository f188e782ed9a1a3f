"""``build_report``: every figure as a PNG and ``index.html`` beside them, in one directory."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..records import atomic_group, atomic_write, atomic_write_text, writable_target
from . import html as pagehtml
from .d_relation import DRelation, d_relation_data
from .prismatic import prismatic_data
from .rotary import rotary_interval_data
from .sample import Sample, classify_days, classify_sample
from .steps import step_simulation_data
from .validation import validation_data

if TYPE_CHECKING:  # pragma: no cover
    from ..analysis import AnovaResult
    from ..calibration import Calibration
    from ..measurements import Traverse

__all__ = ["Report", "build_report"]


class _Plottable(Protocol):
    def plot(self, ax: Any = None) -> Any: ...


@dataclass(frozen=True)
class Report:
    """What :func:`build_report` wrote.

    Attributes
    ----------
    directory, html : Path
        The output directory and its ``index.html``.
    figures : list of Path
        The PNG files, in page order.
    sample : Sample
        How the validated traverses relate to the calibration's own (in-sample or not).
    """

    directory: Path
    html: Path
    figures: list[Path]
    sample: Sample


@dataclass
class _Figures:
    """PNGs written so far, with their captions."""

    out: Path
    dpi: int
    written: list[tuple[Path, str]]

    def save(self, data: _Plottable, name: str, caption: str) -> None:
        """Plot ``data`` into a new figure, write ``name`` and close the figure (never shown)."""
        from ..plotting import pyplot

        axes = np.asarray(data.plot(), dtype=object).reshape(-1)
        fig = axes[0].figure
        path = self.out / name
        kind = path.suffix.lstrip(".").lower() or "png"
        try:  # through a temporary file: a figure from an earlier report stays whole if this fails
            atomic_write(path, lambda f: fig.savefig(f, dpi=self.dpi, format=kind), mode="wb")
        finally:
            pyplot().close(fig)
        self.written.append((path, caption))


_FILES = ("index.html", "fig4_prismatic.png", "fig6_rotary_intervals.png", "fig6_rotary_joint1.png",
          "fig8_simulated_steps.png", "fig9_d_relation.png", "validation.png")  # fmt: skip
"""The files a report may write (figures of a separate validation table end in _validation.png), checked first."""


def build_report(
    calibration: Calibration,
    traverses: Sequence[Traverse],
    directory: str | Path,
    dpi: int = 120,
    seed_simulation: str = "steps",
    validation: Sequence[Traverse] | None = None,
) -> Report:
    """Write the paper-style figures and ``index.html`` into ``directory`` (created if needed).

    Parameters
    ----------
    calibration : Calibration
    traverses : sequence of Traverse
        The table drawn over the model (Figs. 4, 6/10, one panel row per day); also the
        validation table when ``validation`` is None.
    directory : str or Path
    dpi : int
        Resolution of the PNGs.
    seed_simulation : {"steps", "exact"}
        How the paper's Eq. 9 comparator gets its averages: step by step (as the paper
        did) or the exact integral (faster, the same curve to < 1 step in 10^5).
    validation : sequence of Traverse, optional
        A separate validation table: validated and drawn out-of-sample (unless it is
        the calibration's own table, which the provenance sha256 tells).

    The page labels the validation in-sample or out-of-sample
    (:func:`stickslip.report.sample.classify_sample`) in its heading and in every
    figure title. The files are written together (:func:`~stickslip.records.atomic_group`):
    a write that fails (a full disk) leaves every file of an earlier report as it was.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    for name in (*_FILES, *(n.replace(".png", "_validation.png") for n in _FILES[1:4] if validation is not None)):
        writable_target(out / name, "report")  # a folder in a file's place: refused before any is replaced
    ts = list(traverses)
    val_ts = ts if validation is None else list(validation)
    with atomic_group():  # every file or none: a disk full half-way leaves the earlier report whole
        return _write_all(calibration, ts, val_ts, validation is not None, out, dpi, seed_simulation)


def _write_all(calibration: Calibration, ts: list[Traverse], val_ts: list[Traverse], separate: bool, out: Path,
               dpi: int, seed_simulation: str) -> Report:
    """Every figure, then ``index.html`` (inside :func:`build_report`'s group: renamed into place at its end)."""
    sample = classify_sample(calibration, val_ts, separate)
    figs = _Figures(out, dpi, [])
    _model_figures(figs, calibration, ts, False, "")
    if separate:
        _model_figures(figs, calibration, val_ts, True, "_validation")
    rel = _rotary_figures(figs, calibration, seed_simulation)
    notes: list[str] = []
    sections = [_validation_sections(figs, calibration, val_ts, separate, notes)]
    days = sorted({t.day for t in ts})
    sections.insert(0, pagehtml.intro_section(calibration, days, len(ts), notes))
    sections += [
        pagehtml.d_section(rel) if rel is not None else "",
        pagehtml.anova_section(_anova(ts)),
        pagehtml.parameter_section(calibration),
        pagehtml.figure_section(figs.written, calibration.report()),
    ]
    index = out / "index.html"
    atomic_write_text(index, pagehtml.page("stickslip report", [s for s in sections if s]))
    return Report(out, index, [p for p, _ in figs.written], sample)


def _model_figures(figs: _Figures, cal: Calibration, ts: list[Traverse], separate: bool, suffix: str) -> None:
    """Figs. 4 and 6/10: measured traverses over the model, one panel row per day, each labelled."""
    by_day = classify_days(cal, ts, separate)
    labels = {d: s.title for d, s in by_day.items()}
    sample = classify_sample(cal, ts, separate)
    which = f"{sample.kind}: {sample.reason}" if ts else "no traverses: the model alone"
    if 3 in cal.joints:
        figs.save(
            prismatic_data(cal, ts, labels),
            f"fig4_prismatic{suffix}.png",
            "Fig. 4 after the paper: average step of prismatic joint 3 against ζ = ψ − q2, one row per day. "
            "Points: measured traverses; lines: the calibrated Eq. (3), one per tilt θ (and ψ) in the data; "
            f"open squares: the model's value for each traverse. Data {which}.",
        )
    for j in (2, 1):
        if j in cal.joints:
            figs.save(
                rotary_interval_data(cal, ts, j, labels),
                f"fig6_rotary_joint{j}{suffix}.png" if j == 1 else f"fig6_rotary_intervals{suffix}.png",
                f"Figs. 6 and 10 after the paper: average step of joint {j} over each traversed interval "
                "(a bar spans the interval, the point sits at its midpoint), one row per day; open squares: "
                "the model's exact average over the same interval; lines: the pointwise model, Eq. (8), "
                f"per pose. Data {which}.",
            )


def _rotary_figures(figs: _Figures, cal: Calibration, seed_simulation: str) -> DRelation | None:
    """Figs. 8 and 9 of joint 2 (simulations of the calibrated model: no measured data)."""
    if 2 not in cal.joints:
        return None
    figs.save(
        step_simulation_data(cal, 2),
        "fig8_simulated_steps.png",
        "Fig. 8 after the paper: step-by-step simulation of the calibrated joint 2 over its full range at "
        "θ = ψ = 0 (dashed: the average step range/steps; dotted: γ0, the step without gravity torque).",
    )
    rel = d_relation_data(cal, 2, simulate=seed_simulation)
    figs.save(
        rel,
        "fig9_d_relation.png",
        "Fig. 9 after the paper: d against D = γ(θ = 0) − γ0 for a full-range traverse of joint 2. Solid: the "
        "exact relation for several γ0; dashed: the paper's method (quadratic fitted to step-by-step "
        f"simulations), {rel.error_text()}; dotted: Eq. 9 as printed, which gives d < 1 µrad and cannot match "
        "the paper's own Fig. 10.",
    )
    return rel


def _validation_sections(figs: _Figures, cal: Calibration, ts: list[Traverse], separate: bool, notes: list[str]) -> str:
    """The validation figure, table and residuals of the validated traverses, each day labelled."""
    from ..analysis import residual_summary

    modelled = [t for t in ts if (t.joint, t.direction) in cal.models]
    if len(modelled) < len(ts):
        notes.append(
            f"{len(ts) - len(modelled)} traverses of joints/directions this calibration does not "
            "model are left out of the validation"
        )
    if not modelled:
        return ""
    by_day = classify_days(cal, ts, separate)
    sample = classify_sample(cal, ts, separate)
    vf = validation_data(cal, modelled, {d: s.title for d, s in by_day.items()})
    figs.save(
        vf,
        "validation.png",
        f"Validation, {sample.kind}: relative error of the model's prediction (o) and of the constant step (x) "
        f"for every traverse, against the measured average step, one row per day. Data {sample.kind}: {sample.reason}.",
    )
    return (
        pagehtml.validation_section(vf, sample, by_day)
        + "\n"
        + pagehtml.residual_section(residual_summary(cal, modelled), sample)
    )


def _anova(ts: list[Traverse]) -> AnovaResult | None:
    """One-way ANOVA across days and directions, or None when the table has no repeated pose."""
    from ..analysis import anova

    if not ts:
        return None
    try:
        return anova(ts, two_way=False)
    except ValueError:
        return None
