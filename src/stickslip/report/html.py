"""The HTML page of the report: escaped tables and sections, one function each, no plotting."""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._units import param_scale, step_scale

if TYPE_CHECKING:  # pragma: no cover
    from ..analysis import AnovaResult, ResidualSummary
    from ..calibration import Calibration
    from .d_relation import DRelation
    from .sample import Sample
    from .validation import ValidationFigure

__all__ = [
    "table",
    "page",
    "intro_section",
    "validation_section",
    "residual_section",
    "parameter_section",
    "d_section",
    "anova_section",
    "figure_section",
]

CSS = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f2f2f2; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.92em; color: #444; }
.warn { color: #a40; }
.sample { font-weight: bold; }
"""

Columns = Sequence[tuple[str, str]]


def table(rows: Sequence[dict[str, Any]], columns: Columns) -> str:
    """An HTML table: ``columns`` are ``(key, heading)``; every cell is escaped."""
    head = "".join(f"<th>{html.escape(label)}</th>" for _, label in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(r.get(k, '')))}</td>" for k, _ in columns) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def pct(x: float | None) -> str:
    """A fraction as ``"1.23 %"``; empty for None or a non-finite value."""
    return "" if x is None or not math.isfinite(x) else f"{100 * x:.2f} %"


def page(title: str, sections: Sequence[str]) -> str:
    """A self-contained page (inline CSS, figures by relative path)."""
    head = f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
    return "\n".join([head + f"<style>{CSS}</style></head><body>", *sections, "</body></html>"])


def intro_section(calibration: Calibration, days: Sequence[str], n: int, notes: Sequence[str]) -> str:
    """The heading, the table's size and days, the calibration's method and any notes."""
    parts = [
        f"<h1>stickslip report — calibration of {html.escape(str(calibration.day))}</h1>",
        f"<p>{n} traverses from {len(days)} day(s): {html.escape(', '.join(days))}. "
        f"Calibration method: {html.escape(str(calibration.method))}.</p>",
    ]
    parts += [f"<p class='warn'>note: {html.escape(x)}</p>" for x in notes]
    return "\n".join(parts)


def validation_section(fig: ValidationFigure, sample: Sample, by_day: Mapping[str, Sample]) -> str:
    """Model against constant step, per joint and day, each day labelled in-sample or out-of-sample."""
    rows = []
    for c in fig.cells:
        me, ce = np.abs(c.model_error), np.abs(c.constant_error)
        rows.append(
            {
                "joint": c.joint,
                "day": c.day,
                "sample": by_day[c.day].kind if c.day in by_day else "",
                "n": c.n,
                "mmax": pct(float(me.max())),
                "mmean": pct(float(me.mean())),
                "cmax": pct(float(ce.max())),
                "cmean": pct(float(ce.mean())),
            }
        )
    return "\n".join(
        [
            f"<h2>Validation ({html.escape(sample.kind)}): model against constant step</h2>",
            f"<p class='sample'>{html.escape(sample.kind)}: {html.escape(sample.reason)}.</p>",
            "<p>Relative error of the predicted average step over each traverse, per joint and day. The paper "
            "reports a maximum error of about 15 % (prismatic) and 2 % (rotary) for its model, against 40 % and "
            "7 % for a constant step. In-sample errors show how well the model fits the traverses it was "
            "calibrated from, not how well it predicts new ones.</p>",
            table(
                rows,
                [
                    ("joint", "joint"),
                    ("day", "day"),
                    ("sample", "sample"),
                    ("n", "traverses"),
                    ("mmax", "model max"),
                    ("mmean", "model mean"),
                    ("cmax", "constant-step max"),
                    ("cmean", "constant-step mean"),
                ],
            ),
        ]
    )


def residual_section(res: ResidualSummary, sample: Sample) -> str:
    """RMS and largest residual per joint and direction, relative and in nm or µrad."""
    rows = []
    for r in res.rows_:
        k, unit = step_scale(r.joint)
        rows.append(
            {
                "jd": f"{r.joint}{r.direction}",
                "n": r.n,
                "rms": pct(r.rms_rel),
                "max": pct(r.max_rel),
                "rmsa": f"{r.rms_abs * k:.4g} {unit}",
                "maxa": f"{r.max_abs * k:.4g} {unit}",
            }
        )
    return "\n".join(
        [
            f"<h2>Residuals per joint and direction ({html.escape(sample.kind)})</h2>",
            table(
                rows,
                [
                    ("jd", "joint"),
                    ("n", "n"),
                    ("rms", "RMS (relative)"),
                    ("max", "max (relative)"),
                    ("rmsa", "RMS"),
                    ("maxa", "max"),
                ],
            ),
        ]
    )


def parameter_section(calibration: Calibration) -> str:
    """The calibrated parameters with standard errors, in nm, µrad or dimensionless."""
    rows = []
    for p in calibration.parameters():
        k, unit = param_scale(p.name, p.joint)
        rows.append(
            {
                "jd": f"{p.joint}{p.direction}",
                "name": p.name,
                "q3": "" if p.q3 is None else f"{p.q3 * 1e3:g} mm",
                "value": f"{p.value * k:.5g} {unit}".strip(),
                "se": "" if p.stderr is None else f"{p.stderr * k:.3g} {unit}".strip(),
            }
        )
    cols = [("jd", "joint"), ("name", "parameter"), ("q3", "at q3"), ("value", "value"), ("se", "standard error")]
    return "<h2>Calibrated parameters</h2>\n" + table(rows, cols)


def d_section(rel: DRelation) -> str:
    """The calibration's d beside the paper's quadratic at the same D (empty without joint-2 models)."""
    if not rel.calibrated:
        return ""
    k, unit = step_scale(2)
    rows = [
        {
            "jd": f"2{c.direction}",
            "q3": f"{c.q3 * 1e3:g} mm",
            "D": f"{c.delta * k:.3f} {unit}",
            "d": f"{c.d * k:.3f} {unit}",
            "dq": f"{c.d_quadratic * k:.3f} {unit}",
            "err": f"{(c.d_quadratic - c.d) * k:+.3f} {unit}",
        }
        for c in rel.calibrated
    ]
    return "\n".join(
        [
            "<h2>d from the full-range average: exact against the paper's quadratic</h2>",
            "<p>For this calibration's joint-2 models: D is the full-range average step at θ = ψ = 0 minus γ0; "
            "d the calibrated value (exact relation); the paper's method reads d off a quadratic fitted to "
            f"step-by-step simulations. Over the plotted grid the quadratic is {html.escape(rel.error_text())} "
            "(largest where a curve turns steep: there the average step hardly changes with d).</p>",
            table(
                rows,
                [
                    ("jd", "joint"),
                    ("q3", "q3"),
                    ("D", "D"),
                    ("d", "d (exact)"),
                    ("dq", "d (paper's quadratic)"),
                    ("err", "quadratic − exact"),
                ],
            ),
        ]
    )


def anova_section(an: AnovaResult | None) -> str:
    """One-way ANOVA across days and between directions (empty when there is no test)."""
    from ..analysis import PoseGroup

    if an is None or not an.tests:
        return ""
    rows = [
        {
            "test": "across days" if t.test == "day" else "+ vs −",
            "joint": t.joint,
            "what": t.direction if t.test == "day" else t.day,
            "pose": PoseGroup(t.joint, t.pose, t.interval).describe(),
            "n": t.n,
            "F": f"{t.F:.4g}",
            "p": f"{t.p:.3g}",
            "verdict": t.verdict(an.alpha),
        }
        for t in an.tests
    ]
    return "\n".join(
        [
            "<h2>Day-to-day and direction ANOVA</h2>",
            "<p>One-way ANOVA of the average step across days (per joint, direction and repeated pose) and of "
            "+ against − (per joint, day and pose); significant at α = 0.05 means the paper's advice holds: "
            "recalibrate every day, and per direction.</p>",
            table(
                rows,
                [
                    ("test", "test"),
                    ("joint", "joint"),
                    ("what", "day / direction"),
                    ("pose", "pose"),
                    ("n", "n"),
                    ("F", "F"),
                    ("p", "p"),
                    ("verdict", "at α = 0.05"),
                ],
            ),
        ]
    )


def figure_section(figures: Sequence[tuple[Path, str]], calibration_report: str) -> str:
    """Every figure by relative path with its caption, then the calibration's text report."""
    parts = ["<h2>Figures</h2>"]
    for p, caption in figures:
        parts.append(
            f"<figure><img src='{html.escape(p.name)}' alt='{html.escape(p.stem)}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )
    parts.append(f"<h2>Calibration report</h2><pre>{html.escape(calibration_report)}</pre>")
    return "\n".join(parts)
