"""Statistics on measured step sizes: day-to-day ANOVA (the paper's Section 3.1) and fit residuals.

ANOVA
-----
The paper recalibrates every day because a one-way ANOVA of the average step size
``gamma = |end - start| / steps`` across days was significant (p < 0.05), and so was
the difference between the + and - directions within a day. :func:`anova` repeats
those tests on any measurement table:

``day`` tests
    For each joint, direction and *pose*, one-way ANOVA of gamma with the day as the
    factor (:func:`scipy.stats.f_oneway`).
``direction`` tests
    For each joint, day and pose, one-way ANOVA of gamma with the direction as the
    factor (+ against -; equivalent to a pooled two-sample t test, F = t^2).
``two-way`` tests
    For each joint and pose, the two-way table ``gamma ~ C(day) * C(direction)``
    (ordinary least squares, type-II sums of squares, as statsmodels ``anova_lm``
    reports them; computed in closed form from group sums, O(n)): one row per term
    ``day``, ``direction`` and ``day:direction``.

Grouping rule (which traverses are "the same pose")
    Traverses of one joint belong to the same pose when their fixed joints (the moving
    joint's own column is ignored), ``theta``, ``psi`` and the traversed interval
    ``[min(start, end), max(start, end)]`` agree within ``angle_tol`` (rad) for angles
    and ``length_tol`` (m) for lengths -- default 1e-3 rad (0.06 degrees) and 10 µm,
    far below what a pose can be set to by hand and far above rounding in a file.
    Groups are formed greedily: each traverse joins the first group whose first member
    matches it (found through a grid of cells, so grouping costs O(n), not O(n x groups)).

When a test is made
    A ``day`` test needs the pose measured on at least two days and at least one
    degree of freedom within days (``n > number of days``): every traverse of that
    joint, direction and pose enters, grouped by day (a day with a single traverse
    still counts as a group). A ``direction`` test needs both directions in that pose
    on that day and ``n >= 3``. A ``two-way`` table needs at least two days, both
    directions, every day x direction cell filled, and ``n`` greater than the number of
    cells. Poses that do not qualify are listed in :attr:`AnovaResult.skipped`.

If the spread within groups is exactly zero the F statistic is infinite (p = 0) when
the group means differ and undefined (NaN) when they do not.

Residuals
---------
:func:`residual_summary` compares a calibration's exact traverse-average prediction
with every measured traverse: per joint and direction, n, RMS and maximum relative
residual and the same in nm (prismatic) or µrad (rotary).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .measurements import Traverse
from .units import step_scale

if TYPE_CHECKING:  # pragma: no cover
    from .calibration import Calibration

__all__ = [
    "ALPHA",
    "AnovaResult",
    "AnovaTest",
    "PoseGroup",
    "ResidualRow",
    "ResidualSummary",
    "anova",
    "group_poses",
    "one_way",
    "residual_summary",
]

ALPHA = 0.05
ANGLE_TOL = 1e-3
LENGTH_TOL = 1e-5
_POSE_KEYS = ("q1", "q2", "q3", "theta", "psi")


# ---------------------------------------------------------------- pose groups


@dataclass
class PoseGroup:
    """Traverses of one joint in the same pose (see the module's grouping rule).

    Attributes
    ----------
    joint : int
    pose : dict
        ``q1, q2, q3, theta, psi`` of the group's first traverse (rad, m); the moving
        joint's entry is that traverse's column and carries no meaning.
    interval : tuple of float
        ``(min(start, end), max(start, end))`` of the first traverse (rad or m).
    traverses : list of Traverse
    """

    joint: int
    pose: dict[str, float]
    interval: tuple[float, float]
    traverses: list[Traverse] = field(default_factory=list)

    def matches(self, t: Traverse, angle_tol: float, length_tol: float) -> bool:
        if t.joint != self.joint:
            return False
        for k in _POSE_KEYS:
            if k == f"q{t.joint}":
                continue
            tol = length_tol if k == "q3" else angle_tol
            if abs(getattr(t, k) - self.pose[k]) > tol:
                return False
        tol = length_tol if t.joint == 3 else angle_tol
        lo, hi = sorted((t.start, t.end))
        return abs(lo - self.interval[0]) <= tol and abs(hi - self.interval[1]) <= tol

    def describe(self) -> str:
        """Short human label: the fixed joints, tilt and interval with units."""
        parts = []
        for k in _POSE_KEYS:
            if k == f"q{self.joint}":
                continue
            v = self.pose[k]
            name = {"theta": "θ", "psi": "ψ"}.get(k, k)
            parts.append(f"{name}={v * 1e3:.4g}mm" if k == "q3" else f"{name}={math.degrees(v):.4g}°")
        lo, hi = self.interval
        if self.joint == 3:
            parts.append(f"q3:{lo * 1e3:.4g}..{hi * 1e3:.4g}mm")
        else:
            parts.append(f"q{self.joint}:{math.degrees(lo):.4g}..{math.degrees(hi):.4g}°")
        return " ".join(parts)


def group_poses(
    traverses: Sequence[Traverse], angle_tol: float = ANGLE_TOL, length_tol: float = LENGTH_TOL
) -> list[PoseGroup]:
    """Group traverses by joint and pose (fixed joints, tilt, traversed interval).

    The greedy rule of the module docstring (each traverse joins the first group whose
    first member matches it), found through a grid of cells ``2 tol`` wide so that the
    cost grows with the number of traverses, not with traverses x groups: a matching
    first member lies in one of the neighbouring cells, and of the matching groups the
    oldest wins, exactly as in a scan of the list.

    Parameters
    ----------
    traverses : sequence of Traverse
    angle_tol : float
        Largest difference of angles (rad) within one pose.
    length_tol : float
        Largest difference of lengths (m) within one pose.
    """
    if not (0.0 < angle_tol < math.inf and 0.0 < length_tol < math.inf):
        return _group_poses_scan(traverses, angle_tol, length_tol)
    groups: list[PoseGroup] = []
    # per joint: a trie of cell indices (one level per coordinate) whose leaves list group numbers
    tries: dict[int, dict[int, Any]] = {}
    # a traverse whose coordinates equal an earlier one's joins that one's group
    exact: dict[tuple[int, tuple[float, ...]], int] = {}
    for t in traverses:
        coords, tols = _pose_coordinates(t, angle_tol, length_tol)
        key = (t.joint, coords)
        hit = exact.get(key)
        if hit is None:
            scaled = [c / (2.0 * tol) for c, tol in zip(coords, tols, strict=True)]
            if not all(map(math.isfinite, scaled)):  # huge or NaN values (not from a table): no grid
                return _group_poses_scan(traverses, angle_tol, length_tol)
            cells = [math.floor(x) for x in scaled]
            trie = tries.setdefault(t.joint, {})
            best = -1
            for gi in _neighbours(trie, cells, 0):
                if (best < 0 or gi < best) and groups[gi].matches(t, angle_tol, length_tol):
                    best = gi
            if best < 0:
                lo, hi = sorted((t.start, t.end))
                groups.append(PoseGroup(t.joint, t.pose(), (lo, hi), []))
                best = len(groups) - 1
                node = trie
                for c in cells[:-1]:
                    node = node.setdefault(c, {})
                node.setdefault(cells[-1], []).append(best)
            hit = exact[key] = best
        groups[hit].traverses.append(t)
    return groups


def _pose_coordinates(t: Traverse, angle_tol: float, length_tol: float) -> tuple[tuple[float, ...], list[float]]:
    """The coordinates :meth:`PoseGroup.matches` compares, and the tolerance of each."""
    coords: list[float] = []
    tols: list[float] = []
    for k in _POSE_KEYS:
        if k == f"q{t.joint}":
            continue
        coords.append(float(getattr(t, k)))
        tols.append(length_tol if k == "q3" else angle_tol)
    lo, hi = sorted((t.start, t.end))
    tol = length_tol if t.joint == 3 else angle_tol
    coords += [float(lo), float(hi)]
    tols += [tol, tol]
    return tuple(coords), tols


def _neighbours(node: dict[int, Any], cells: list[int], level: int) -> Iterator[int]:
    """Group numbers stored in the trie within one cell of ``cells`` on every level."""
    c = cells[level]
    for k in (c - 1, c, c + 1):
        child = node.get(k)
        if child is None:
            continue
        if level == len(cells) - 1:
            yield from child
        else:
            yield from _neighbours(child, cells, level + 1)


def _group_poses_scan(traverses: Sequence[Traverse], angle_tol: float, length_tol: float) -> list[PoseGroup]:
    """The greedy rule by a plain scan (for tolerances of zero, below zero or infinite)."""
    groups: list[PoseGroup] = []
    for t in traverses:
        for g in groups:
            if g.matches(t, angle_tol, length_tol):
                g.traverses.append(t)
                break
        else:
            lo, hi = sorted((t.start, t.end))
            groups.append(PoseGroup(t.joint, t.pose(), (lo, hi), [t]))
    return groups


# ---------------------------------------------------------------- tests


def one_way(samples: Sequence[Sequence[float] | NDArray[np.float64]]) -> tuple[float, float, int, int]:
    """One-way ANOVA of ``samples`` (one sequence per group): ``(F, p, df_between, df_within)``.

    The F test of :func:`scipy.stats.f_oneway` computed directly (two-pass sums of
    squares, p from the F distribution's survival function): the same numbers without
    its per-call overhead, which dominated tables of many days. The degenerate cases are
    explicit: zero spread within groups gives F = inf, p = 0 if the means differ (NaN
    otherwise); equal group means give F = 0, p = 1.
    """
    from scipy import special

    arrays = [np.asarray(s, dtype=float) for s in samples]
    k = len(arrays)
    n = sum(a.size for a in arrays)
    dfb, dfw = k - 1, n - k
    if k < 2 or dfw < 1 or any(a.size == 0 for a in arrays):
        raise ValueError(
            f"one-way ANOVA needs >= 2 non-empty groups and n > groups (got {k} groups, n = {n})"
        )
    every = np.concatenate(arrays)
    grand = every.mean()
    ssw = sum(float(((a - a.mean()) ** 2).sum()) for a in arrays)
    ssb = sum(a.size * float((a.mean() - grand) ** 2) for a in arrays)
    scale = max(float(np.abs(every).max()), 1e-300) ** 2 * n
    if ssw <= 1e-28 * scale:
        if ssb <= 1e-28 * scale:
            return math.nan, math.nan, dfb, dfw
        return math.inf, 0.0, dfb, dfw
    F = max(0.0, (ssb / dfb) / (ssw / dfw))
    return F, float(special.fdtrc(dfb, dfw, F)), dfb, dfw


@dataclass(frozen=True)
class AnovaTest:
    """One F test.

    Attributes
    ----------
    test : {"day", "direction", "two-way"}
    joint : int
    direction : str or None
        For ``day`` tests (``None`` otherwise).
    day : str or None
        For ``direction`` tests (``None`` otherwise).
    term : str or None
        For ``two-way`` rows: ``"day"``, ``"direction"`` or ``"day:direction"``.
    pose : dict
        ``q1, q2, q3, theta, psi`` (rad, m) the test grouped on.
    interval : tuple of float
        Traversed interval of the moving joint (rad or m).
    F, p : float
    df_num, df_den : int
        Degrees of freedom of the term and of the residual.
    n : int
        Traverses in the test.
    groups : list of dict
        ``{"label", "n", "mean", "sd"}`` per level of the factor, mean and sd in the
        display unit (nm or µrad).
    unit : str
    """

    test: str
    joint: int
    direction: str | None
    day: str | None
    term: str | None
    pose: dict[str, float]
    interval: tuple[float, float]
    F: float
    p: float
    df_num: int
    df_den: int
    n: int
    groups: tuple[dict[str, Any], ...] = ()
    unit: str = ""

    def significant(self, alpha: float = ALPHA) -> bool:
        """Whether p < alpha (False for an undefined p)."""
        return bool(self.p < alpha)

    def verdict(self, alpha: float = ALPHA) -> str:
        if not math.isfinite(self.p):
            return "undefined (no spread)"
        return "significant" if self.significant(alpha) else "not significant"

    def as_dict(self, alpha: float = ALPHA) -> dict[str, Any]:
        d: dict[str, Any] = {"test": self.test, "joint": self.joint}
        if self.test == "day":
            d["direction"] = self.direction
        elif self.test == "direction":
            d["day"] = self.day
        else:
            d["term"] = self.term
        d.update(
            pose=dict(self.pose),
            interval=list(self.interval),
            F=self.F,
            p=self.p,
            df_num=self.df_num,
            df_den=self.df_den,
            n=self.n,
            significant=self.significant(alpha),
            alpha=alpha,
            groups=[dict(g) for g in self.groups],
            unit=self.unit,
        )
        return d


def _groups_summary(
    labels: Sequence[str], samples: Sequence[NDArray[np.float64]], joint: int
) -> tuple[dict[str, Any], ...]:
    k, _unit = step_scale(joint)
    out = []
    for lab, s in zip(labels, samples, strict=True):
        sd = float(np.std(s, ddof=1) * k) if s.size > 1 else math.nan
        out.append({"label": lab, "n": int(s.size), "mean": float(s.mean() * k), "sd": sd})
    return tuple(out)


@dataclass
class AnovaResult:
    """All tests of :func:`anova`, with what was skipped and why.

    Attributes
    ----------
    tests : list of AnovaTest
    skipped : list of str
        One line per pose or cell that could not be tested, with the reason.
    alpha : float
        Significance level of the verdicts.
    """

    tests: list[AnovaTest]
    skipped: list[str]
    alpha: float = ALPHA

    def rows(self) -> list[dict[str, Any]]:
        """One JSON-ready dict per test (see :meth:`AnovaTest.as_dict`)."""
        return [t.as_dict(self.alpha) for t in self.tests]

    def report(self) -> str:
        """Plain-text table of every test with F, p and the verdict."""
        lines = [f"ANOVA of the average step size (alpha = {self.alpha:g})"]
        if not self.tests:
            lines.append("  no testable groups (a pose must be repeated; see the skipped list)")
        for t in self.tests:
            what = {
                "day": f"days      joint {t.joint}{t.direction}",
                "direction": f"+ vs -    joint {t.joint} day {t.day}",
                "two-way": f"two-way   joint {t.joint} {t.term}",
            }[t.test]
            pose = PoseGroup(t.joint, t.pose, t.interval).describe()
            lines.append(
                f"  {what:<36} F({t.df_num},{t.df_den}) = {t.F:10.4g}  p = {t.p:.3g}  "
                f"{t.verdict(self.alpha):<16} [{pose}]"
            )
        if self.skipped:
            lines.append(f"skipped ({len(self.skipped)}):")
            lines += [f"  {s}" for s in self.skipped]
        return "\n".join(lines)


def _two_way(
    gamma: NDArray[np.float64], day: Sequence[str], plus: NDArray[np.bool_]
) -> list[tuple[str, float, float, int, int]]:
    """Type-II two-way ANOVA of ``gamma ~ C(day) * C(direction)`` in closed form, O(n).

    With every day x direction cell filled (the caller checks it), the residual sums of
    the four nested models follow from group sums: within days, within directions,
    within cells, and the additive model ``day + direction``, whose direction effect is
    the within-day regression on the direction indicator. The type-II sums are
    ``SS(day | direction) = RSS(direction) - RSS(day + direction)``, the same for
    direction, and ``SS(day:direction) = RSS(day + direction) - RSS(cells)`` -- what
    statsmodels' ``anova_lm(ols(...).fit(), typ=2)`` reports (the tests compare them),
    without building an n x (2 days) design matrix.
    """
    from scipy import special

    y = np.asarray(gamma, dtype=float)
    x = plus.astype(float)
    _, d_idx = np.unique(np.asarray(day, dtype=object).astype(str), return_inverse=True)
    n_days = int(d_idx.max()) + 1
    cell = d_idx * 2 + plus.astype(np.intp)

    def within(groups: NDArray[np.intp], v: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        """``v`` minus the mean of its group."""
        cnt = np.bincount(groups, minlength=k)
        return v - (np.bincount(groups, weights=v, minlength=k) / np.maximum(cnt, 1))[groups]

    yd, xd = within(d_idx, y, n_days), within(d_idx, x, n_days)
    rss_day = float(yd @ yd)
    yc = within(cell, y, 2 * n_days)
    rss_cells = float(yc @ yc)
    ydir = within(plus.astype(np.intp), y, 2)
    rss_dir = float(ydir @ ydir)
    sxx = float(xd @ xd)
    b = float(xd @ yd) / sxx if sxx > 0 else 0.0
    r_add = yd - b * xd
    rss_add = float(r_add @ r_add)
    df_res = y.size - 2 * n_days
    terms = (
        ("day", rss_dir - rss_add, n_days - 1),
        ("direction", rss_day - rss_add, 1),
        ("day:direction", rss_add - rss_cells, n_days - 1),
    )
    out = []
    mse = rss_cells / df_res
    for term, ss, df in terms:
        with np.errstate(divide="ignore", invalid="ignore"):
            F = float(np.float64(ss / df) / np.float64(mse))
        if math.isfinite(F) and F < 0.0:  # a sum of squares of -1e-30 from rounding: no effect at all
            F, p = 0.0, 1.0
        else:
            p = float(special.fdtrc(df, df_res, F)) if not math.isnan(F) else math.nan
        out.append((term, F, p, df, df_res))
    return out


def anova(
    traverses: Sequence[Traverse],
    alpha: float = ALPHA,
    two_way: bool = True,
    angle_tol: float = ANGLE_TOL,
    length_tol: float = LENGTH_TOL,
) -> AnovaResult:
    """Day-to-day and direction ANOVA of the average step size, as the paper's Section 3.1.

    Parameters
    ----------
    traverses : sequence of Traverse
        A measurement table (any joints, days and poses).
    alpha : float
        Significance level for the verdicts, in (0, 1).
    two_way : bool
        Also compute the day x direction table with interaction.
    angle_tol, length_tol : float
        Pose-matching tolerances, rad and m (see the module docstring).

    Returns
    -------
    AnovaResult
        ``day`` tests, then ``direction`` tests, then ``two-way`` rows.
    """
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    if not traverses:
        raise ValueError("no traverses to analyse")
    day_tests: list[AnovaTest] = []
    dir_tests: list[AnovaTest] = []
    tw_tests: list[AnovaTest] = []
    skipped: list[str] = []
    for g in sorted(group_poses(traverses, angle_tol, length_tol), key=lambda g: g.joint):
        # the group's average steps by (direction, day), in table order, in one pass
        cells: dict[tuple[str, str], list[float]] = {}
        for t in g.traverses:
            cells.setdefault((t.direction, t.day), []).append(t.gamma)
        day_tests += _day_tests(g, cells, skipped)
        dir_tests += _direction_tests(g, cells, skipped)
        if two_way:
            tw_tests += _two_way_tests(g, cells, skipped)
    return AnovaResult(day_tests + dir_tests + tw_tests, skipped, alpha)


def _test(kind: str, g: PoseGroup, stat: tuple[float, float, int, int], n: int, **kw: Any) -> AnovaTest:
    """An :class:`AnovaTest` of ``kind`` on group ``g`` from ``(F, p, df1, df2)``."""
    F, p, df1, df2 = stat
    return AnovaTest(
        kind, g.joint, kw.get("direction"), kw.get("day"), kw.get("term"), dict(g.pose), g.interval,
        F, p, df1, df2, n, kw.get("groups", ()), step_scale(g.joint)[1],
    )


def _day_tests(g: PoseGroup, cells: dict[tuple[str, str], list[float]], skipped: list[str]) -> list[AnovaTest]:
    """Across days, per direction (the paper's day-to-day question)."""
    where = f"joint {g.joint} [{g.describe()}]"
    all_days = sorted({day for _, day in cells})
    out = []
    for d in ("+", "-"):
        days = [day for day in all_days if (d, day) in cells]
        if not days:
            continue
        n_d = sum(len(cells[(d, day)]) for day in days)
        if len(days) < 2:
            skipped.append(f"days: {where} {d}: measured on one day only ({days[0]})")
            continue
        if n_d <= len(days):
            skipped.append(f"days: {where} {d}: one traverse per day, no spread within days")
            continue
        samples = [np.array(cells[(d, day)]) for day in days]
        out.append(_test("day", g, one_way(samples), n_d, direction=d, groups=_groups_summary(days, samples, g.joint)))
    return out


def _direction_tests(g: PoseGroup, cells: dict[tuple[str, str], list[float]], skipped: list[str]) -> list[AnovaTest]:
    """+ against -, per day."""
    where = f"joint {g.joint} [{g.describe()}]"
    out = []
    for day in sorted({day for _, day in cells}):
        plus = np.array(cells.get(("+", day), []))
        minus = np.array(cells.get(("-", day), []))
        if plus.size == 0 or minus.size == 0:
            continue
        if plus.size + minus.size < 3:
            skipped.append(f"direction: {where} day {day}: one traverse each way, no spread")
            continue
        summary = _groups_summary(["+", "-"], [plus, minus], g.joint)
        out.append(_test("direction", g, one_way([plus, minus]), int(plus.size + minus.size), day=day, groups=summary))
    return out


def _two_way_tests(g: PoseGroup, cells: dict[tuple[str, str], list[float]], skipped: list[str]) -> list[AnovaTest]:
    """Day x direction with interaction (type II), where every day has both directions and a residual."""
    where = f"joint {g.joint} [{g.describe()}]"
    all_days = {day for _, day in cells}
    if len(all_days) < 2 or len({d for d, _ in cells}) < 2:
        return []
    if len(cells) < 2 * len(all_days):
        skipped.append(f"two-way: {where}: not every day has both directions")
        return []
    if len(g.traverses) <= len(cells):
        skipped.append(f"two-way: {where}: one traverse per day and direction, no residual")
        return []
    k, _ = step_scale(g.joint)
    gam = np.array([t.gamma * k for t in g.traverses])
    pl = np.array([t.direction == "+" for t in g.traverses])
    return [
        _test("two-way", g, (F, p, dfn, dfd), len(g.traverses), term=term)
        for term, F, p, dfn, dfd in _two_way(gam, [str(t.day) for t in g.traverses], pl)
    ]


# ---------------------------------------------------------------- fit residuals


@dataclass(frozen=True)
class ResidualRow:
    """Residuals of one joint and direction: measured minus predicted average step.

    Attributes
    ----------
    joint : int
    direction : str
    n : int
    rms_rel, max_rel : float
        RMS and largest absolute relative residual, ``(measured - predicted) / measured``
        (fraction; multiply by 100 for %).
    rms_abs, max_abs : float
        The same in SI (m or rad).
    """

    joint: int
    direction: str
    n: int
    rms_rel: float
    max_rel: float
    rms_abs: float
    max_abs: float

    @property
    def unit(self) -> str:
        return step_scale(self.joint)[1]

    def as_dict(self) -> dict[str, Any]:
        k, unit = step_scale(self.joint)
        return {
            "joint": self.joint,
            "direction": self.direction,
            "n": self.n,
            "rms_rel_percent": 100 * self.rms_rel,
            "max_rel_percent": 100 * self.max_rel,
            f"rms_{'nm' if self.joint == 3 else 'urad'}": self.rms_abs * k,
            f"max_{'nm' if self.joint == 3 else 'urad'}": self.max_abs * k,
            "rms_si": self.rms_abs,
            "max_si": self.max_abs,
        }


@dataclass
class ResidualSummary:
    """Residuals of a calibration against a measurement table, per joint and direction."""

    rows_: list[ResidualRow]

    def rows(self) -> list[dict[str, Any]]:
        return [r.as_dict() for r in self.rows_]

    def report(self) -> str:
        lines = [
            "Residuals (measured - model average over each traverse)",
            "  joint  n     RMS %    max %    RMS        max",
        ]
        for r in self.rows_:
            k, unit = step_scale(r.joint)
            lines.append(
                f"  {r.joint}{r.direction:<4} {r.n:<4} "
                f"{100 * r.rms_rel:7.3f}  {100 * r.max_rel:7.3f}  "
                f"{r.rms_abs * k:8.4g} {unit:<4} {r.max_abs * k:8.4g} {unit}"
            )
        return "\n".join(lines)


def residual_summary(calibration: Calibration, traverses: Sequence[Traverse]) -> ResidualSummary:
    """Residuals of ``calibration`` on ``traverses`` (only joints/directions it models).

    The prediction for a traverse is the exact average step over its interval
    (``calibration.predict``), so long rotary traverses are compared fairly.
    """
    out: list[ResidualRow] = []
    by_key: dict[tuple[int, str], list[Traverse]] = {}
    for t in traverses:
        by_key.setdefault((t.joint, t.direction), []).append(t)
    for joint, d in sorted(by_key, key=lambda k: (k[0], k[1] != "+")):
        ts = by_key[(joint, d)]
        try:
            pred = calibration.predict_many(ts)  # vectorised: one closed form per joint and direction
        except (KeyError, ValueError, LookupError):
            continue  # the calibration does not model this joint/direction
        meas = np.array([t.gamma for t in ts])
        res = meas - pred
        rel = res / meas
        out.append(
            ResidualRow(
                joint,
                d,
                len(ts),
                float(np.sqrt(np.mean(rel**2))),
                float(np.max(np.abs(rel))),
                float(np.sqrt(np.mean(res**2))),
                float(np.max(np.abs(res))),
            )
        )
    return ResidualSummary(out)
