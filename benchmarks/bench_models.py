"""Model benchmark on three independent physics arms (docs/models.md; issue 33).

For each arm (``tests/support/arm_days.py``: the library's physics arm, the LuGre arm, the
Dahl arm written for issue 33 and never tuned to), several seeds and three days each:

* the paper's 14 calibration traverses, 32 more at poses spread over the load space (8 poses
  per joint, both directions; ``calibration.design.spread_poses``), then each joint's first
  paper pose traversed again in both directions (4 repeats: the drift within the session,
  docs/models.md §4), and validation traverses at random poses of the workspace, 64 per
  joint and day in both directions (256 a day; ``--validation-poses``): the largest errors
  and the intervals' coverage are taken over all of them (``--error-poses``), 576
  traverses per joint and direction over 9 days (docs/models-log.md, twelfth round: until
  then 16 poses, the errors over the first 8; ``--validation-poses 16 --error-poses 8``
  gives that run again, the same numbers);
* calibrations: the constant step (the paper's comparator, from the 14), the paper's
  procedure on the 14, the paper's form fitted to the 46 by least squares, ``--model auto``
  on the 46, ``--model auto`` on the 46 and the 4 repeats (the table a calibration with the
  repeat writes), and yesterday's ``auto`` (with the repeats) updated with 4 of today's
  traverses (one per joint and direction, random poses, measured after the first 16 validation
  poses on the same arm, before the others; ``--prior``);
* the largest |relative error| of the predicted average step at the validation traverses,
  per joint (3 prismatic, 2 rotary) and day: the median and the worst day, the mean over
  all; how many days ``auto`` (with the repeats) erred more than the paper's procedure on
  the same day, beside how many the draw of the poses alone would give (the share of the sets of
  M of the day's N validation poses on which it does, summed over days; ``arm_days.share_above``;
  of N / 2 when M = N, where the draw of all N is the count itself);
* the 95 % intervals of ``auto`` with the repeats (``predict --interval``): the share of
  validation traverses inside, per joint and direction, with its 95 % Wilson interval, side
  by side with the same calibration's interval without its drift term ("no drift": the bias the
  fit leaves at the session's end, measured by the repeats' residuals, docs/models.md §4) and
  with ``auto`` on the 46 alone ("46": no repeat, so no drift term, as before); and how honest
  the error ``calibrate`` prints is: the expected RMS error at new poses, and the
  cross-validation RMS of the average, each over the validation traverses' actual RMS error
  (median over days; 1 = honest);
* both verdicts again over the first 8, 16, 32, ... of the day's validation poses (what a run with
  that many gives), and the coverage's spread between the days against binomial sampling's.

Prints Markdown tables (the README's). Run: ``.venv/bin/python benchmarks/bench_models.py``
(a few minutes on 2 cores); ``--seeds 101,102`` and ``--arms dahl`` to choose.

``--resample physics:202:1 --poses 150`` (arm, seed, day 1-3) diagnoses one day instead: the
largest error's validation pose, then ``--poses`` more random poses per joint measured on the
same arm after the day, and how often a day's 8 validation poses would show ``auto``'s
largest error above the paper's procedure's (docs/models-log.md, eighth round).

``--new-per-direction 3`` updates yesterday's ``auto`` with 3 of today's traverses per joint and direction
(12 a day, at random poses) in the ``--prior`` row instead of 1 (docs/models-log.md, eleventh round).

``--check 0,4`` runs each arm without and with check traverses at 4 random poses per joint (both
directions, ``calibration.design.check_poses``; measured after the day's other traverses, not fitted): ``auto``
(with the repeats) is ``calibrate(..., check=...)``, its intervals scaled by how those erred (docs/models.md §4;
docs/models-log.md, seventeenth round); the rows "ARM, check N" side by side with "ARM" (the same traverses
otherwise, so the same fits and errors).

``--design3 maximin`` spreads joint 3's 8 poses by the maximin design instead of its default
(maximum projection; ``calibration.design.spread_poses``), for a side-by-side comparison: the
random poses drawn are the same (docs/models-log.md, ninth round).
"""

from __future__ import annotations

import dataclasses
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "support"))

from arm_days import ARMS, Day, make_day, share_above, wilson_interval  # noqa: E402
from physics_scenarios import random_pose  # noqa: E402

from stickslip import kinematics as kin  # noqa: E402
from stickslip.calibration import Calibration, calibrate  # noqa: E402
from stickslip.calibration.groups import load_coordinates_of, nearest  # noqa: E402
from stickslip.calibration.intervals import relative_sd  # noqa: E402
from stickslip.calibration.selection import calibrate_families  # noqa: E402
from stickslip.calibration.update import update_calibration  # noqa: E402
from stickslip.measurements import Traverse  # noqa: E402

DAYS = ("2026-09-01", "2026-09-02", "2026-09-03")
TARGET = {3: 0.075, 2: 0.035}
ROWS = ("constant step (14)", "paper's procedure (14)", "paper's form, least squares (46)", "auto (46)",
        "auto (46 + 4 repeats)", "yesterday's auto + 4 today (--prior)")
AUTO = ROWS[4]
"""The calibration whose intervals and fallbacks are measured (the design with the repeats)."""


FIRST_POSES = 16
"""Random validation poses per joint and day the day's own generator draws (``make_day``); more are measured
after the day's other traverses (``make_day(more_validation=...)``), so that these 16 and every other table
are the same whatever the number."""
VALIDATION_POSES = 64
"""Random validation poses per joint and day (both directions) by default (``--validation-poses``): the
coverage is over all (docs/models-log.md, twelfth round: why 64)."""
ERROR_POSES = 64
"""The first of them the largest errors are taken over by default (``--error-poses``); until the twelfth
round 8 of 16."""
RESAMPLE_SET = 8
"""``--resample``: the size of the sets of poses drawn (the eighth round's day)."""
LADDER = (8, 16, 32, 64, 128, 256, 512)
"""The pose counts the verdicts are shown at, up to the day's validation poses."""


@dataclasses.dataclass
class _Tally:
    """One arm's results over its days (see :func:`run_arm`)."""

    errs: dict[str, dict[int, list[np.ndarray]]] = dataclasses.field(
        default_factory=lambda: defaultdict(lambda: {3: [], 2: []}))
    inside: dict[tuple[str, int, str], list[np.ndarray]] = dataclasses.field(
        default_factory=lambda: defaultdict(list))
    """Whether each validation traverse is inside its interval, one array a day, in the poses' order."""
    pose_err: dict[int, list[tuple[np.ndarray, np.ndarray]]] = dataclasses.field(
        default_factory=lambda: {3: [], 2: []})
    """Each day's errors of ``auto`` and of the paper's procedure at its validation poses (each pose's larger
    error of + and -)."""
    honest: dict[str, dict[int, list[float]]] = dataclasses.field(
        default_factory=lambda: {"expected": {3: [], 2: []}, "cv": {3: [], 2: []}})
    fallback: dict[int, int] = dataclasses.field(default_factory=lambda: {3: 0, 2: 0})
    drift: dict[tuple[int, str], list[float]] = dataclasses.field(default_factory=lambda: defaultdict(list))
    days: int = 0

    def above(self, joint: int, poses: int) -> tuple[int, float]:
        """Days ``auto``'s largest error over the first ``poses`` validation poses of ``joint`` is above the
        procedure's, and how many the draw of ``poses`` of the day's poses gives (the sum over the days of the
        share of the ``poses``-subsets on which it is; :func:`arm_days.share_above`)."""
        seen = sum(int(a[:poses].max() > p[:poses].max()) for a, p in self.pose_err[joint])
        return seen, sum(share_above(a, p, poses) for a, p in self.pose_err[joint])

    def coverage(self, key: tuple[str, int, str], poses: int | None = None) -> tuple[int, int]:
        """Traverses inside the interval and in all, over the first ``poses`` validation poses of each day."""
        ok = np.concatenate([x[:poses] for x in self.inside[key]])
        return int(ok.sum()), int(ok.size)


def _first(val: list[Traverse], poses: int) -> list[Traverse]:
    """The traverses at the first ``poses`` validation poses of each joint (both directions)."""
    return [t for j in (3, 2) for t in [t for t in val if t.joint == j][: 2 * poses]]


def _errors(pred: np.ndarray, val: list[Traverse]) -> dict[int, np.ndarray]:
    e = np.abs(np.asarray(pred, dtype=float) / np.array([t.gamma for t in val]) - 1.0)
    return {j: e[[t.joint == j for t in val]] for j in (3, 2)}


def _pose_errors(cal: Calibration, val: list[Traverse], joint: int) -> np.ndarray:
    """``cal``'s larger |relative error| of + and - at each validation pose of ``joint``, in their order."""
    ts = [t for t in val if t.joint == joint]
    return np.abs(cal.predict_many(ts) / np.array([t.gamma for t in ts]) - 1.0).reshape(-1, 2).max(axis=1)


def _without_drift(cal: Calibration) -> Calibration:
    """``cal`` with its intervals' drift term set to zero (the same fit and error model otherwise)."""
    pred = {k: dataclasses.replace(p, drift=0.0, drift_sd=0.0) for k, p in cal.predictive.items()}
    return dataclasses.replace(cal, predictive=pred)


def _inside(cals: dict[str, Calibration], val: list[Traverse]) -> dict[tuple[str, int, str], np.ndarray]:
    """Whether each validation traverse is inside its 95 % interval, by joint and direction, for each
    named calibration."""
    out: dict[tuple[str, int, str], np.ndarray] = {}
    for j in (3, 2):
        for d in "+-":
            ts = [t for t in val if t.joint == j and t.direction == d]
            cols = [np.array([getattr(t, k) for t in ts]) for k in ("q1", "q2", "q3", "theta", "psi")]
            for name, cal in cals.items():
                sd = relative_sd(cal, j, d, *cols)
                e = np.abs(cal.predict_many(ts) / np.array([t.gamma for t in ts]) - 1.0)
                out[(name, j, d)] = e <= 1.96 * sd
    return out


def _day(tally: _Tally, d: Day, prev: Calibration | None, poses: tuple[int, int]) -> Calibration:
    """One day into ``tally`` (``poses``: the validation poses per joint, and the first of them the largest
    errors are taken over); returns the day's ``auto`` (with the repeats, checked by the day's check
    traverses if any), tomorrow's prior."""
    c14 = calibrate(d.paper14)
    auto46 = calibrate(d.calibration46, model="auto")
    auto = calibrate(d.calibration, model="auto", check=d.check)
    everything = _first(d.validation + d.more_validation, poses[0])
    val = _first(everything, poses[1])
    rows = {
        ROWS[0]: np.array([c14.constant_step(t.joint, t.direction) for t in val]),
        ROWS[1]: c14.predict_many(val),
        ROWS[2]: calibrate(d.calibration46, method="lsq").predict_many(val),
        ROWS[3]: auto46.predict_many(val),
        AUTO: auto.predict_many(val),
    }
    if prev is not None:
        rows[ROWS[5]] = update_calibration(prev, d.new4 + d.more_new)[0].predict_many(val)
    for label, pred in rows.items():
        for j, e in _errors(pred, val).items():
            tally.errs[label][j].append(e)
    for key, ok in _inside({"now": auto, "no drift": _without_drift(auto), "46": auto46}, everything).items():
        tally.inside[key].append(ok)
    e_auto = _errors(rows[AUTO], val)
    for j in (3, 2):
        for s in "+-":
            pr = auto.predictive[(j, s)]
            tally.drift[(j, s)].append(float(np.hypot(pr.drift, pr.drift_sd)))
        tally.pose_err[j].append((_pose_errors(auto, everything, j), _pose_errors(c14, everything, j)))
        sel = auto.selection[(j, "+")]
        tally.fallback[j] += int(bool(sel.get("fallback")))
        rms = float(np.sqrt(np.mean(e_auto[j] ** 2)))
        expected = np.sqrt(np.mean([auto.sigma_model[(j, s)] ** 2 for s in "+-"]))
        cv = float(sel.get("cv_rms") or np.nan)  # type: ignore[arg-type]
        tally.honest["expected"][j].append(float(expected) / rms)
        tally.honest["cv"][j].append(cv / rms)
    tally.days += 1
    return auto


def run_arm(arm: str, seeds: tuple[int, ...], new_per_direction: int = 1, validation_poses: int = VALIDATION_POSES,
            error_poses: int = ERROR_POSES, check: int = 0) -> _Tally:
    """Every day of one arm: errors per calibration (over the first ``error_poses`` validation poses per joint),
    coverage (over all ``validation_poses``), honesty ratios, fallbacks (the update with ``new_per_direction``
    of today's traverses per joint and direction); ``check`` poses per joint of check traverses."""
    tally = _Tally()
    more = max(0, validation_poses - FIRST_POSES)
    for seed in seeds:
        rng = np.random.default_rng(seed)
        prev = None
        for day in DAYS:
            d = make_day(arm, seed, day, rng, validation_poses=FIRST_POSES, repeat_first=True,
                         new_per_direction=new_per_direction, more_validation=more, check_per_joint=check)
            prev = _day(tally, d, prev, (validation_poses, error_poses))
    return tally


def _print_errors(results: dict[str, _Tally]) -> None:
    print("| arm | calibration | prismatic max, median day | worst day | mean | rotary max, median day | "
          "worst day | mean |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for arm, res in results.items():
        for label in ROWS:
            by_j = res.errs[label]
            cells = []
            for j in (3, 2):
                if by_j[j]:
                    day_max = np.array([x.max() for x in by_j[j]])
                    cells += [f"{100 * np.median(day_max):.1f} %", f"{100 * day_max.max():.1f} %",
                              f"{100 * np.concatenate(by_j[j]).mean():.1f} %"]
                else:
                    cells += ["—"] * 3
            print(f"| {arm} | {label} | " + " | ".join(cells) + " |")


def _cell(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{100 * k / n:.1f} % ({100 * lo:.1f}–{100 * hi:.1f})"


def _print_verdicts(results: dict[str, _Tally], error_poses: int, validation_poses: int) -> None:
    """The main table: days above over ``error_poses``, beside what the draw of that many of the day's
    ``validation_poses`` gives (of half of them when the two are equal: the draw of all is the count itself)."""
    drawn = error_poses if error_poses < validation_poses else max(1, validation_poses // 2)
    print(f"\n| arm | days | auto above the paper's procedure over {error_poses} poses (prismatic / rotary days; "
          f"expected from the draw of {drawn} of the day's {validation_poses}) | fell back to the paper's "
          "form | 95 % interval holds (Wilson 95 %): 3+ | 3- | 2+ | 2- | expected error / actual RMS (3 / 2) | "
          "CV RMS / actual RMS (3 / 2) |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for arm, res in results.items():
        cov = []
        for j in (3, 2):
            for d in "+-":
                nod, c46 = (100 * np.divide(*res.coverage((name, j, d))) for name in ("no drift", "46"))
                cov.append(f"{_cell(*res.coverage(('now', j, d)))}; no drift {nod:.1f}; 46 {c46:.1f} %")
        h = res.honest
        (w3, _), (w2, _) = res.above(3, error_poses), res.above(2, error_poses)
        c3, c2 = res.above(3, drawn)[1], res.above(2, drawn)[1]
        print(f"| {arm} | {res.days} | {w3} / {w2} ({c3:.1f} / {c2:.1f}) | {res.fallback[3]} / {res.fallback[2]} | "
              + " | ".join(cov) + " | "
              f"{np.median(h['expected'][3]):.2f} / {np.median(h['expected'][2]):.2f} | "
              f"{np.median(h['cv'][3]):.2f} / {np.median(h['cv'][2]):.2f} |")


def _print_ladder(results: dict[str, _Tally], validation_poses: int) -> None:
    """The two verdicts over the first 8, 16, ... validation poses of each day (what a run with that many
    gives: the first poses are the same), and the coverage's spread between the days."""
    ladder = [m for m in LADDER if m < validation_poses] + [validation_poses]
    print("\nThe verdicts over the first N validation poses per joint and day: days auto's\n"
          "largest error is above the procedure's (expected from the draw of N of the\n"
          "day's poses), and the 95 % interval's coverage (Wilson 95 %)\n")
    print("| arm | N | above, days 3 / 2 (expected) | 3+ | 3- | 2+ | 2- |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for arm, res in results.items():
        for m in ladder:
            (w3, c3), (w2, c2) = res.above(3, m), res.above(2, m)
            cells = [_cell(*res.coverage(("now", j, d), m)) for j in (3, 2) for d in "+-"]
            print(f"| {arm} | {m} | {w3} / {w2} ({c3:.1f} / {c2:.1f}) | " + " | ".join(cells) + " |")
    print(f"\nThe days' coverage at N = {validation_poses}: sd between the days, and the sd that\n"
          "binomial sampling of N poses alone gives, sqrt(p (1 - p) / N) (a ratio above 1:\n"
          "the days differ, and the Wilson interval, which treats every traverse as\n"
          "independent, is the error from the poses on these days only)\n")
    print("| arm | 3+ | 3- | 2+ | 2- |\n| --- | ---: | ---: | ---: | ---: |")
    for arm, res in results.items():
        cells = []
        for j in (3, 2):
            for d in "+-":
                per_day = np.array([x.mean() for x in res.inside[("now", j, d)]])
                p = float(per_day.mean())
                binom = np.sqrt(max(p * (1 - p), 1e-12) / validation_poses)
                cells.append(f"{100 * per_day.std(ddof=1):.1f} / {100 * binom:.1f}")
        print(f"| {arm} | " + " | ".join(cells) + " |")


def main(seeds: tuple[int, ...] = (101, 102, 103), arms: tuple[str, ...] = ("physics", "lugre", "dahl"),
         new_per_direction: int = 1, validation_poses: int = VALIDATION_POSES, error_poses: int = ERROR_POSES,
         checks: tuple[int, ...] = (0,)) -> None:
    print(f"seeds {', '.join(map(str, seeds))}; days {', '.join(DAYS)}")
    print(f"{4 * error_poses} validation traverses a day for the errors ({error_poses} poses per joint), "
          f"{4 * validation_poses} for\nthe coverage ({len(seeds) * len(DAYS) * validation_poses} per joint and "
          f"direction over {len(seeds) * len(DAYS)} days)")
    print("Largest |relative error| of a day's validation traverses on the median and the worst day, and the")
    print("mean over all; the issue's targets with 46 traverses: 7.5 % / 3.5 % on the median day, and never")
    print("above the paper's procedure on the same day.\n")
    if new_per_direction != 1:
        print(f"The --prior row: yesterday's auto updated with {4 * new_per_direction} of today's traverses "
              f"({new_per_direction} per joint and direction), not 4.\n")
    if checks != (0,):
        print("Rows 'ARM, check N': auto's intervals checked by N random poses per joint (docs/models.md §4).\n")
    results = {arm if c == 0 else f"{arm}, check {c}": run_arm(arm, seeds, new_per_direction, validation_poses,
                                                              error_poses, c)
               for arm in arms for c in checks}
    _print_errors(results)
    _print_verdicts(results, error_poses, validation_poses)
    _print_ladder(results, validation_poses)
    print("\nThe drift term (docs/models.md §4): what the intervals add for the bias the fit leaves at the "
          "session's end, sqrt(drift^2 + drift_sd^2), mean and range over the days")
    print("\n| arm | 3+ | 3- | 2+ | 2- |\n| --- | ---: | ---: | ---: | ---: |")
    for arm, res in results.items():
        dr = res.drift
        cells = [f"{100 * np.mean(dr[k]):.2f} % ({100 * min(dr[k]):.2f}…{100 * max(dr[k]):.2f})"
                 for k in ((3, "+"), (3, "-"), (2, "+"), (2, "-"))]
        print(f"| {arm} | " + " | ".join(cells) + " |")


def _pose(t: Traverse) -> kin.Pose:
    return kin.Pose(t.q1, t.q2, t.q3, t.theta, t.psi)


def resample_day(arm: str, seed: int, day_index: int, poses: int) -> None:
    """One day of ``run_arm`` again (day ``day_index`` from 1), diagnosed: per joint, the pose of
    ``auto``'s largest validation error (load coordinates, distance to the nearest calibrated pose),
    then ``poses`` random poses measured on a replay of the day's arm after its traverses: the largest
    and RMS errors (each pose's larger of + and -) of ``auto``, the paper's procedure (14) and the
    paper's form on the 46 + 4, and the share of 4000 sets of 8 of those poses on which ``auto``'s
    largest error is above the procedure's."""
    rng = np.random.default_rng(seed)
    for day in DAYS[:day_index]:
        d = make_day(arm, seed, day, rng, validation_poses=FIRST_POSES, repeat_first=True)
    cals = {"auto": calibrate(d.calibration, model="auto"), "procedure": calibrate(d.paper14),
            "form": calibrate_families(d.calibration, model="paper")}
    replay = ARMS[arm](seed, day)
    for t in d.paper14 + d.spread32 + d.repeat + d.validation:
        replay.traverse(t.joint, t.direction, _pose(t), day)
    draw = np.random.default_rng(999)
    for j in (3, 2):
        val = [t for t in _first(d.validation, RESAMPLE_SET) if t.joint == j]
        e = np.abs(cals["auto"].predict_many(val) / np.array([t.gamma for t in val]) - 1.0)
        w = val[int(np.argmax(e))]
        cal = np.array([[t.q1, t.q2, t.q3, t.theta, t.psi] for t in d.calibration if t.joint == j])
        at = load_coordinates_of(j, np.array([[w.q1, w.q2, w.q3, w.theta, w.psi]]))
        dist = float(nearest(at, load_coordinates_of(j, cal))[0][0])
        sel = cals["auto"].selection[(j, "+")]
        print(f"{arm} seed {seed} {day} joint {j}: auto {sel['chosen']} (fell back: {sel['fallback']}); largest "
              f"validation error {100 * e.max():.2f} % at {w.direction} {np.round(at[0], 2).tolist()}, "
              f"{dist:.2f} from the nearest calibrated pose")
        ts = [replay.traverse(j, s, p, day) for p in [random_pose(draw, j) for _ in range(poses)] for s in "+-"]
        g = np.array([t.gamma for t in ts])
        err = {n: np.abs(c.predict_many(ts) / g - 1.0).reshape(poses, 2).max(axis=1) for n, c in cals.items()}
        sets = np.array([draw.choice(poses, RESAMPLE_SET, replace=False) for _ in range(4000)])
        top = {n: x[sets].max(axis=1) for n, x in err.items()}
        print(f"  {poses} more poses: largest " + ", ".join(f"{n} {100 * x.max():.2f} %" for n, x in err.items())
              + "; RMS " + ", ".join(f"{n} {100 * np.sqrt(np.mean(x**2)):.2f} %" for n, x in err.items()))
        print(f"  sets of {RESAMPLE_SET}: auto's largest above the procedure's in "
              f"{100 * np.mean(top['auto'] > top['procedure']):.1f} %, the form's in "
              f"{100 * np.mean(top['form'] > top['procedure']):.1f} %")


def _design3(criterion: str) -> None:
    """Spread joint 3's poses in :func:`make_day` by ``criterion`` (the rotary joints keep their default)."""
    import arm_days

    from stickslip.calibration.design import spread_poses

    def spread(joint: int, n: int, seed: int = 0, existing: list[kin.Pose] | None = None) -> list[kin.Pose]:
        return spread_poses(joint, n, seed, existing=existing, criterion=criterion if joint == 3 else None)

    arm_days.spread_poses = spread  # type: ignore[assignment]


def _cli(argv: list[str]) -> None:
    import argparse

    def ints(text: str) -> tuple[int, ...]:
        try:
            return tuple(int(v) for v in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: seeds are integers separated by commas") from None

    def arms(text: str) -> tuple[str, ...]:
        out = tuple(text.split(","))
        unknown = [a for a in out if a not in ARMS]
        if unknown:
            raise argparse.ArgumentTypeError(f"{', '.join(unknown)}: not an arm ({', '.join(ARMS)})")
        return out

    def poses(text: str) -> int:
        if not text.isdigit() or not 1 <= int(text) <= 512:
            raise argparse.ArgumentTypeError(f"{text!r}: a number of poses from 1 to 512")
        return int(text)

    def checks(text: str) -> tuple[int, ...]:
        out = tuple(text.split(","))
        if not all(v.isdigit() and int(v) <= 16 for v in out) or len(set(out)) != len(out):
            raise argparse.ArgumentTypeError(f"{text!r}: check poses per joint, 0-16, separated by commas")
        return tuple(int(v) for v in out)

    def days(text: str) -> list[tuple[str, int, int]]:
        out = []
        for spec in text.split(","):
            parts = spec.split(":")
            if len(parts) != 3 or parts[0] not in ARMS or not parts[1].isdigit() or not parts[2].isdigit():
                raise argparse.ArgumentTypeError(f"{spec!r}: ARM:SEED:DAY, e.g. physics:202:1")
            out.append((parts[0], int(parts[1]), int(parts[2])))
        return out

    ap = argparse.ArgumentParser(
        description="Largest errors, interval coverage and fallbacks of the calibrations on three "
        "independent arms (docs/models.md; issue 33). Without options: the benchmark's seeds "
        "101-103 on every arm, 64 validation poses per joint and day, about 2 minutes of CPU "
        "(--validation-poses 16 --error-poses 8: the reading before the twelfth round, about 1).",
    )
    ap.add_argument("--seeds", type=ints, default=(101, 102, 103), help="seeds, e.g. 201,202 (default 101,102,103)")
    ap.add_argument("--arms", type=arms, default=tuple(ARMS), help=f"arms, some of {','.join(ARMS)}")
    ap.add_argument("--check", type=checks, default=(0,), metavar="N,...",
                    help="check poses per joint, 0-16, e.g. 0,4 for both side by side (default 0: none)")
    ap.add_argument("--design3", choices=("maximin", "maxpro"), help="joint 3's spread design (default: the library's)")
    ap.add_argument("--resample", type=days, help="ARM:SEED:DAY,...: one day's largest error on more random poses")
    ap.add_argument("--poses", type=int, default=150, help="random poses for --resample (default 150)")
    ap.add_argument("--validation-poses", type=poses, default=VALIDATION_POSES, metavar="N",
                    help=f"random validation poses per joint and day, 1-512 (default {VALIDATION_POSES}): "
                    "the coverage is over all; more than 16 are measured after the day's other traverses")
    ap.add_argument("--error-poses", type=poses, default=ERROR_POSES, metavar="M",
                    help=f"the first M of them the largest errors are over, at most N (default {ERROR_POSES})")
    ap.add_argument("--new-per-direction", type=int, default=1, choices=range(1, 9), metavar="N",
                    help="the --prior row's new traverses per joint and direction, 1-8 (default 1: 4 a day)")
    a = ap.parse_args(argv)
    if a.error_poses > a.validation_poses:
        ap.error(f"--error-poses {a.error_poses}: at most --validation-poses ({a.validation_poses})")
    if a.design3:
        _design3(a.design3)
    if a.resample:
        for arm, seed, day in a.resample:
            resample_day(arm, seed, day, a.poses)
        return
    main(seeds=a.seeds, arms=a.arms, new_per_direction=a.new_per_direction, validation_poses=a.validation_poses,
         error_poses=a.error_poses, checks=a.check)


if __name__ == "__main__":
    _cli(sys.argv[1:])
