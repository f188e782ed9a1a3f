"""Scaling benchmark: how each command's time and peak memory grow with the table's rows.

For each command and size the table is written to a temporary folder and the command is
run in a fresh Python process (so that its peak memory is its own), timed inside that
process around the command itself (start-up is measured on its own, below). From each
series the growth exponent k of ``time ~ rows^k`` is fitted over the two largest sizes
(k = 1: linear; 2: quadratic). Baselines run side by side in the same run:

* predict: a plain numpy evaluation of the same closed form on the same columns
  (parsing with ``numpy.loadtxt``), i.e. what a user would write by hand;
* anova: scipy's ``f_oneway`` and statsmodels' ``ols`` + ``anova_lm`` on the same
  groups, given the groups (no parsing, no pose grouping);
* planner: the same moves by adaptive quadrature per move (scipy ``quad``) and by
  stepping through the move one step at a time;
* calibrate: at the largest size, the same command with the chosen families' refit to every
  traverse run to convergence (5 Levenberg-Marquardt steps, as before) instead of one step;
* start-up: ``stickslip --help`` against a bare ``python -c pass``.

The audio path (our detector against aubio and librosa onset detection) is
``bench_audio.py``.

Run: ``.venv/bin/python benchmarks/bench_scale.py`` (``make bench``; sizes 1e3 .. 1e6,
several minutes) or ``--quick`` (tiny sizes, seconds: what CI runs through
``tests/test_bench_smoke.py``). ``--markdown`` also prints the table for the README;
``--only calibrate`` (names separated by commas) runs those commands' sizes only.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"

FULL = {
    "predict": (1_000, 10_000, 100_000, 1_000_000),
    "calibrate": (1_000, 10_000, 100_000),
    "fit": (1_000, 10_000, 100_000),
    "anova": (1_000, 3_000, 10_000),
    "import": (1_000, 10_000, 100_000, 1_000_000),
}
# --quick shows that every command runs and that the growth exponent is computed: two sizes for one command
# (calibrate), one for the others; each size is a child process of about a second
QUICK = {k: (60, 120) if k == "calibrate" else (60,) for k in FULL}


# ----------------------------------------------------------------------------- tables


def measurement_table(path: Path, n: int, seed: int = 0, distinct_poses: bool = False) -> None:
    """``n`` traverses: the paper's calibration poses (joints 3 and 2, both ways) over many days.

    Steps are drawn around the model's prediction (0.3 % noise), values written to 7
    significant digits as a logger would. With ``distinct_poses`` every row has a pose
    of its own (the worst case for pose grouping).
    """
    sys.path.insert(0, str(HERE.parent / "tests" / "support"))
    from synth import paper_table

    rng = np.random.default_rng(seed)
    base = paper_table()
    lines = ["day,joint,direction,q1,q2,q3,theta,psi,start,end,steps"]
    for i in range(n):
        t = base[i % len(base)]
        day = (datetime.date(2026, 1, 1) + datetime.timedelta(days=i // (3 * len(base)))).isoformat()  # 3 repeats a day
        q2, theta = t.q2, t.theta
        if distinct_poses:
            if t.joint == 3:
                q2 = -math.pi / 2 + 1.5 * rng.random()
            theta = -math.pi / 2 * rng.random()
        steps = max(1, round(t.steps * (1 + 0.003 * rng.standard_normal())))
        lines.append(
            f"{day},{t.joint},{t.direction},{t.q1:.7g},{q2:.7g},{t.q3:.7g},{theta:.7g},{t.psi:.7g},"
            f"{t.start:.7g},{t.end:.7g},{steps}"
        )
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def pose_table(path: Path, n: int, seed: int = 0) -> None:
    """``n`` poses of joint 3 (step at a pose) and joint 2 (average over a traverse), alternating, each
    with a day and a note passed through (about 90 bytes a row: a million rows are about 90 MB)."""
    rng = np.random.default_rng(seed)
    q2 = rng.uniform(-3.6, 0.5, n)
    q3 = rng.uniform(0.0, 0.012, n)
    th = rng.uniform(-1.5, 0.0, n)
    lines = ["joint,direction,q1,q2,q3,theta,psi,start,end,day,note"]
    for i in range(n):
        note = f"2026-05-11,sample {i:08d} under the objective"
        if i % 2:
            lines.append(f"3,{'+-'[i % 4 // 2]},0,{q2[i]:.7g},0,{th[i]:.7g},0,,,{note}")
        else:
            lines.append(f"2,,0,0,{q3[i]:.7g},{th[i]:.7g},0,0.5,-3.5,{note}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def history_table(path: Path, n: int, seed: int = 0) -> None:
    """A lab's history of ``n`` traverses: sessions of the paper's 14 calibration poses and 86 random
    ones (``tests/support/synth.py``), what ``calibrate`` meets after months of daily calibrations."""
    sys.path.insert(0, str(HERE.parent / "tests" / "support"))
    from synth import history_csv

    path.write_text(history_csv(n, seed), encoding="utf-8")


# ----------------------------------------------------------------------------- child process


def child(argv: Sequence[str]) -> None:
    """Run one command in this process; print its time (s) and this process's peak memory (MiB).

    ``BENCH_REFIT_ITERATIONS`` in the environment sets the refit of a long table's chosen families
    (``calibration.selection.FULL_REFIT_ITERATIONS``): the baseline of ``calibrate``, the refit run
    to convergence as before issue 33's second round, side by side.
    """
    from stickslip.cli import app

    if os.environ.get("BENCH_REFIT_ITERATIONS"):
        from stickslip.calibration import selection

        selection.FULL_REFIT_ITERATIONS = int(os.environ["BENCH_REFIT_ITERATIONS"])

    t = time.perf_counter()
    cpu0 = time.process_time()
    try:
        app(list(argv), standalone_mode=False)
        code = 0
    except SystemExit as e:  # pragma: no cover - a failed command
        code = int(e.code or 0)
    dt = time.perf_counter() - t
    cpu = time.process_time() - cpu0
    print(json.dumps({"seconds": dt, "cpu_seconds": cpu, "peak_mib": peak_mib(), "exit": code}))


def peak_mib() -> float:
    """This process's peak resident memory, MiB (VmHWM: its own, not inherited over fork like ru_maxrss)."""
    try:
        for ln in Path("/proc/self/status").read_text().splitlines():
            if ln.startswith("VmHWM:"):
                return int(ln.split()[1]) / 1024
    except OSError:  # pragma: no cover - not Linux
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / (1024 if sys.platform != "darwin" else 1024**2)


def run_child(argv: Sequence[str], env: dict[str, str]) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, __file__, "--child", *argv], capture_output=True, text=True, env=env, check=False
    )
    last = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if not last:
        raise RuntimeError(f"{argv[0]} failed: {out.stderr.strip()[-500:]}")
    res = json.loads(last[-1])
    if res["exit"]:
        raise RuntimeError(f"{argv[0]} exited {res['exit']}: {out.stderr.strip()[-500:]}")
    return res


# ----------------------------------------------------------------------------- baselines


def numpy_predict(path: Path) -> float:
    """Plain numpy on pandas' C CSV reader: load the columns, evaluate the closed forms, no checks, no output."""
    sys.path.insert(0, str(HERE.parent / "tests" / "support"))
    import pandas as pd
    from synth import PAPER_PRISMATIC, PAPER_ROTARY

    from stickslip.models import gamma_prismatic, steps_between

    t = time.perf_counter()
    f = pd.read_csv(path, usecols=["joint", "q2", "q3", "theta", "start", "end"], dtype=float)
    joint, q2, q3, th, st, en = (f[c].to_numpy() for c in ("joint", "q2", "q3", "theta", "start", "end"))
    a = joint
    out = np.empty(len(a))
    j3 = joint == 3
    p = PAPER_PRISMATIC["+"]
    out[j3] = gamma_prismatic(q2[j3], th[j3], 0.0, p.a, p.b, p.c)
    r = PAPER_ROTARY["-"]
    j2 = ~j3
    g0, d = r.at(q3[j2])
    n = steps_between(st[j2], en[j2], g0, d * np.cos(th[j2]) * 0.0, -d * np.cos(th[j2]))
    out[j2] = np.abs(en[j2] - st[j2]) / n
    return time.perf_counter() - t


def anova_baselines(path: Path) -> dict[str, float]:
    """scipy f_oneway and statsmodels ols + anova_lm on the same pose groups (grouping given)."""
    from scipy import stats

    from stickslip.analysis import group_poses
    from stickslip.measurements import read_measurements

    groups = [g for g in group_poses(read_measurements(path)) if len({t.day for t in g.traverses}) > 1]
    out: dict[str, float] = {}
    warnings.simplefilter("ignore")  # tiny groups: scipy warns about them (our anova skips them)
    t = time.perf_counter()
    for g in groups:
        for d in "+-":
            days: dict[str, list[float]] = {}
            for tr in g.traverses:
                if tr.direction == d:
                    days.setdefault(tr.day, []).append(tr.gamma)
            if len(days) > 1:
                stats.f_oneway(*days.values())
    out["scipy f_oneway (groups given)"] = time.perf_counter() - t
    try:
        import pandas as pd
        import statsmodels.formula.api as smf
        from statsmodels.stats.anova import anova_lm
    except ImportError:  # pragma: no cover
        return out
    warnings.simplefilter("ignore")  # after statsmodels' import, which sets some filters to "always"
    t = time.perf_counter()
    for g in groups:
        if len({(x.day, x.direction) for x in g.traverses}) >= len(g.traverses):
            continue  # no residual degrees of freedom: our anova skips it too
        df = pd.DataFrame(
            {"gamma": [x.gamma * 1e9 for x in g.traverses], "day": [x.day for x in g.traverses],
             "direction": [x.direction for x in g.traverses]}
        )
        anova_lm(smf.ols("gamma ~ C(day) * C(direction)", data=df).fit(), typ=2)
    out["statsmodels ols + anova_lm (groups given)"] = time.perf_counter() - t
    return out


def planner_rows(moves: int) -> list[tuple[str, float]]:
    sys.path.insert(0, str(HERE.parent / "tests" / "support"))
    from synth import paper_table

    from stickslip.calibration import calibrate
    from stickslip.kinematics import Pose
    from stickslip.models import simulate_traverse_steps, steps_between_quad
    from stickslip.motion.planning import Planner, plan_move

    cal = calibrate(paper_table())
    pose = Pose(q3=0.006, theta=-0.3)
    planner = Planner(cal, 2, pose)
    A, al, be = (float(x) for x in cal.model(2, "-").rotary_coefficients(0, 0, 0.006, -0.3, 0))
    rng = np.random.default_rng(1)
    pairs = [(float(a), float(b)) for a, b in rng.uniform(-3.5, 0.5, (moves, 2)) if a > b]

    def per_move(fn: Callable[[float, float], object], pairs: list[tuple[float, float]]) -> float:
        best = math.inf
        for _ in range(3):
            t = time.perf_counter()
            for a, b in pairs:
                fn(a, b)
            best = min(best, (time.perf_counter() - t) / len(pairs))
        return best

    x, w = np.polynomial.legendre.leggauss(16)

    def gauss(a: float, b: float) -> float:
        """The naive planner: steps = integral of dq / gamma(q) by 16-point Gauss-Legendre, numpy, per move."""
        q = 0.5 * (b - a) * x + 0.5 * (a + b)
        return abs(0.5 * (b - a) * float(np.dot(w, 1.0 / (A + al * np.cos(q) + be * np.sin(q)))))

    return [
        ("Planner.steps", per_move(planner.steps, pairs)),
        ("Planner.plan (with dead reckoning)", per_move(planner.plan, pairs)),
        ("plan_move (new pose each call)", per_move(lambda a, b: plan_move(cal, 2, a, b, pose), pairs)),
        ("per-move Gauss-Legendre, 16 nodes (numpy)", per_move(gauss, pairs)),
        ("per-move quadrature (scipy quad)", per_move(lambda a, b: steps_between_quad(a, b, A, al, be), pairs[:200])),
        (
            "per-move step-by-step simulation",
            per_move(
                lambda a, b: simulate_traverse_steps(a, b, lambda q: A + al * math.cos(q) + be * math.sin(q)),
                pairs[:5],
            ),
        ),
    ]


def startup(env: dict[str, str], runs: int = 7) -> tuple[float, float]:
    """Fastest wall time of ``stickslip --help`` and of a bare ``python -c pass`` over ``runs`` (s).

    The fastest run is the cost without other processes competing (a shared machine
    only ever adds time).
    """

    def med(cmd: list[str]) -> float:
        ts = []
        for _ in range(runs):
            t = time.perf_counter()
            subprocess.run(cmd, capture_output=True, env=env, check=True)
            ts.append(time.perf_counter() - t)
        return float(np.min(ts))

    cli = "import sys; from stickslip.cli import main; sys.argv = ['stickslip', '--help']; main()"
    return med([sys.executable, "-c", cli]), med([sys.executable, "-c", "pass"])


# ----------------------------------------------------------------------------- main


def exponent(ns: Sequence[int], ts: Sequence[float]) -> float:
    """Growth exponent over the two largest sizes: log(t2 / t1) / log(n2 / n1)."""
    return math.log(ts[-1] / ts[-2]) / math.log(ns[-1] / ns[-2])


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for ln in Path("/proc/cpuinfo").read_text().splitlines():
            if ln.startswith("model name"):
                cpu = ln.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    py = platform.python_version()
    return f"{cpu}, {os.cpu_count()} cores, Python {py}, numpy {np.__version__}, {platform.system()}"


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["--child"]:
        child(args[1:])
        return []
    quick = "--quick" in args
    sizes = QUICK if quick else FULL
    if "--only" in args:  # e.g. --only calibrate: that command's sizes, then the rest as usual
        sizes = {k: v for k, v in sizes.items() if k in args[args.index("--only") + 1].split(",")}
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    rows: list[dict[str, object]] = []
    print(f"machine: {machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        cal = d / "cal.json"  # a family calibration (its intervals depend on the pose) for predict
        history_table(d / "cal.csv", QUICK["calibrate"][-1] if quick else 1000)  # quick: only that it runs
        run_child(["calibrate", str(d / "cal.csv"), "-o", str(cal), "--json"], env)
        head = f"{'command':10s} {'rows':>9s} {'seconds':>9s} {'cpu s':>8s} {'µs/row':>8s} {'peak MiB':>9s}"
        print(f"\n{head}   baseline")
        for cmd, ns in sizes.items():
            times, cpus = [], []
            for n in ns:
                meas = d / f"m{n}.csv"
                base = ""
                if cmd == "predict":
                    pose_table(d / f"p{n}.csv", n)
                    argv_ = ["predict", str(d / f"p{n}.csv"), "-c", str(cal), "-o", str(d / "out.csv"), "--interval"]
                    tb = numpy_predict(d / f"p{n}.csv")
                    base = f"pandas read_csv + numpy closed form: {tb:.3g} s"
                else:
                    if cmd == "calibrate":
                        history_table(meas, n)
                    else:
                        measurement_table(meas, n, distinct_poses=(cmd == "anova"))
                    argv_ = {
                        "calibrate": ["calibrate", str(meas), "-o", str(d / f"cal{n}.json")],
                        "fit": ["fit", str(meas), "--json"],
                        "anova": ["anova", str(meas), "--json"],
                        "import": ["import", str(meas), "-d", "sim://", "--db", str(d / f"db{n}.sqlite"), "--json"],
                    }[cmd]
                r = run_child(argv_, env)
                if cmd == "calibrate" and n == ns[-1] and not quick:  # the refit to convergence, side by side
                    rb = run_child(argv_, {**env, "BENCH_REFIT_ITERATIONS": "5"})
                    base = (f"refit to convergence (5 steps): {rb['seconds']:.3g} s, {rb['cpu_seconds']:.3g} CPU s "
                            f"({rb['seconds'] / r['seconds']:.2f}x)")
                times.append(float(r["seconds"]))
                cpus.append(float(r["cpu_seconds"]))
                rows.append({"command": cmd, "rows": n, **r})
                sec, cpu, peak = r["seconds"], r["cpu_seconds"], r["peak_mib"]
                print(f"{cmd:10s} {n:9d} {sec:9.3f} {cpu:8.3f} {sec / n * 1e6:8.2f} {peak:9.0f}   {base}")
            if len(ns) > 1:
                k, kc = exponent(ns, times), exponent(ns, cpus)
                rows.append({"command": cmd, "exponent": k, "exponent_cpu": kc})
                print(f"{cmd:10s} growth exponent {k:.2f} wall, {kc:.2f} CPU (time ~ rows^k, two largest sizes)")
        if "anova" in sizes:  # anova with repeats (pose groups that are tested), against scipy and statsmodels
            n = sizes["anova"][-1]
            measurement_table(d / "rep.csv", n)
            r = run_child(["anova", str(d / "rep.csv"), "--json"], env)
            print(f"\nanova, {n} rows in 14 repeated poses: {r['seconds']:.3f} s (grouping, one-way and two-way tests)")
            for name, t in anova_baselines(d / "rep.csv").items():
                print(f"  baseline {name}: {t:.3f} s")
    print("\nplanning one move of joint 2 (µs per move)")
    prow = planner_rows(40 if quick else 2000)
    base = prow[0][1]
    for name, t in prow:
        print(f"  {name:40s} {t * 1e6:10.2f} {t / base:8.1f}x")
    pr = dict(prow)
    quad, plan, gl = pr["per-move quadrature (scipy quad)"], pr["Planner.plan (with dead reckoning)"], pr[
        "per-move Gauss-Legendre, 16 nodes (numpy)"
    ]
    print(f"  Planner.steps is {gl / base:.1f}x faster than the naive numpy Gauss-Legendre planner, "
          f"{quad / base:.1f}x than scipy quad; Planner.plan {quad / plan:.1f}x faster than scipy quad")
    rows.append({"planner_steps_us": base * 1e6, "planner_plan_us": plan * 1e6, "gauss_us": gl * 1e6,
                 "quadrature_us": quad * 1e6})
    helpt, bare = startup(env, 1 if quick else 7)
    print(f"\nstart-up: stickslip --help {helpt:.3f} s, bare python {bare:.3f} s ({helpt / bare:.1f}x)")
    rows.append({"startup_help_s": helpt, "startup_python_s": bare})
    return rows


if __name__ == "__main__":
    main()
