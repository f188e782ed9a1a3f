"""Away from the tuning's step rate: the confirmed detector on four independent generators.

Every arm of the battery's generator (``tests/support/battery_sound.py``: joints P and Q, five kinds of
stop), the fourth (``tests/support/modal_sound.py``: arms 1-6, four kinds), the fifth
(``tests/support/arrival_sound.py``: arms 1-8, three kinds) and the sixth (``tests/support/beam_sound.py``: beams
1-10) is tuned by ``tune`` on its own 1000 Hz tuning recording and then heard, as ``listen`` hears it
(every fire confirmed by its persistence), at 900, 950, 975, 1025, 1050 and 1100 Hz: one recording
per rate, its seed the rate. 68 tunings x 6 rates = 408 recordings. The first confirmed event is
counted as ``bench_audio.py --onset`` counts it:

* **right**: onset within 25 ms of the true stop, not flagged;
* **flagged**: the event says ``onset_uncertain`` (a traverse refuses it: no count, never a wrong one);
* **early** / **late**: onset more than 25 ms off and not flagged: a *silently wrong count*;
* **missed**: no event (a traverse times out).

Each recording's stepping before the stop (cut 0.1 s before it) is also heard alone: an event there
is a false stop (**fired**).

With ``--drive N`` it also draws N random arms of the seventh generator (``tests/support/drive_sound.py``:
the piezo's drive tone through the mount, unchanged at the stop) at 950-1050 Hz, the space of
``tests/test_audio_drive.py``'s property (``--seed`` picks the draws).

Run: ``.venv/bin/python benchmarks/bench_audio_rates.py`` (about 10 minutes on 2 cores);
``--sets battery,modal`` for some sets; ``--drive 160 --sets none`` for the drive draws alone;
``--stop-scale arm`` renders the beams' stop at a loudness fixed per arm (``beam_sound``'s docstring) in place of
each recording's own (the default).
Measured on main at session 27's end (``daa96af``), with ``--drive 160``: right 366, flagged 16,
missed 25, silently wrong 1 (the fifth generator's arm 3, shifted stop, early at 1100 Hz), no fire on
stepping alone; the drive draws (seed 1): right 134, flagged 7, missed 16, refused 3, none silently
wrong. With round 12b (session 28; the predicted drops): right 370, flagged 17, missed 20, early 1;
the drive draws unchanged. ``make bench`` runs every set and 60 drive draws.
"""

from __future__ import annotations

import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "support"))

import arrival_sound as ar  # noqa: E402
import battery_sound as bs  # noqa: E402
import beam_sound as bm  # noqa: E402
import drive_sound as dv  # noqa: E402
import modal_sound as md  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector  # noqa: E402
from stickslip.audio.detector import Tuning, detector_for  # noqa: E402
from stickslip.audio.tuning import TuningError, tune  # noqa: E402

SR = 48_000
TOL_S = 0.025
RATES_HZ = (900.0, 950.0, 975.0, 1025.0, 1050.0, 1100.0)
SETS = ("battery", "modal", "arrival", "beam")
OUTCOMES = ("right", "flagged", "early", "late", "missed")

# (name, training samples, training stop s, test maker: rate Hz -> (samples, stop s))
Case = tuple[str, np.ndarray, float, Callable[[float], tuple[np.ndarray, float]]]


def cases(which: str, stop_scale: str = "recording") -> Iterator[Case]:
    """The tunings of one set, each with a maker of its test recording at a step rate.

    ``stop_scale``: the beams' stop loudness, per recording or fixed per arm (``beam_sound.Scene.stop_scale``).
    """
    if which == "battery":
        for joint, seed in (("P", 1), ("Q", 2)):
            for kind in ("louder", "quieter", "duller", "brighter", "spectral"):
                train = bs.render(bs.Scene(joint, 1000.0, 2.0, 3.0, seed=seed, stop_kind=kind))[0]

                def make_b(r: float, joint: str = joint, kind: str = kind) -> tuple[np.ndarray, float]:
                    return bs.render(bs.Scene(joint, r, 1.6, 2.2, seed=int(r), stop_kind=kind))[0], 1.6

                yield f"battery {joint} {kind}", train, 2.0, make_b
    elif which == "modal":
        for arm in range(1, 7):
            for kind in md.KINDS:
                train = md.render(md.Scene(arm, kind, stop_at=3.0, dur=4.5, seed=10))

                def make_m(r: float, arm: int = arm, kind: str = kind) -> tuple[np.ndarray, float]:
                    return md.render(md.Scene(arm, kind, stop_at=2.0, dur=3.0, rate=r, seed=int(r))), 2.0

                yield f"modal {arm} {kind}", train, 3.0, make_m
    elif which == "arrival":
        for arm in range(1, 9):
            for kind in ar.STOP_KINDS:
                a = ar.Arm(arm, kind)

                def make_a(r: float, a: ar.Arm = a) -> tuple[np.ndarray, float]:
                    return ar.render(ar.Scene(arm=a, rate=r, seed=int(r))), 2.0

                yield f"arrival {arm} {kind}", ar.render(ar.tuning_scene(a)), 2.0, make_a
    elif which == "beam":
        for b in range(1, 11):
            beam = bm.Beam(b)

            def make_bm(r: float, beam: bm.Beam = beam) -> tuple[np.ndarray, float]:
                return bm.render(bm.Scene(beam=beam, rate=r, seed=int(r), stop_scale=stop_scale)), 2.0

            yield f"beam {b}", bm.render(bm.tuning_scene(beam)), 2.0, make_bm
    else:
        raise SystemExit(f"error: no set {which!r}; choose from {', '.join(SETS)}")


def outcome(tu: Tuning, y: np.ndarray, stop_s: float | None, commanded_hz: float | None = None) -> str:
    """The first confirmed event, counted: right / flagged / early / late / missed, or fired (stop_s None).

    ``commanded_hz``: the step rate the controller commands, told to the detector as a traverse tells it.
    """
    det = ConfirmedStopDetector(detector_for(tu))
    det.reset(0.0, step_rate_hz=commanded_hz)
    events = det.feed(np.asarray(y, dtype=np.float32)) + det.finish()
    if not events:
        return "missed"
    if stop_s is None:
        return "fired"
    ev = events[0]
    if ev.onset_uncertain:
        return "flagged"
    err = ev.onset_s - stop_s
    return "early" if err < -TOL_S else "late" if err > TOL_S else "right"


def run_sets(
    sets: list[str], rates: tuple[float, ...] = RATES_HZ, commanded: bool = False, stop_scale: str = "recording"
) -> None:
    print("| set | rates | n | right | flagged | early | late | missed | stepping alone fired |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    total: Counter[str] = Counter()
    wrong: list[str] = []
    for which in sets:
        near: Counter[str] = Counter()
        far: Counter[str] = Counter()
        t0 = time.perf_counter()
        for name, train, stop_s, make in cases(which, stop_scale):
            try:
                tu = tune(train, SR, stop_s, seed=0)
            except TuningError:
                print(f"  ({name}: tune refused its 1000 Hz recording)", file=sys.stderr)
                continue
            for r in rates:
                y, stop = make(r)
                hz = r if commanded else None
                o = outcome(tu, y, stop, hz)
                fired = outcome(tu, y[: int((stop - 0.1) * SR)], None, hz) == "fired"
                c = near if abs(r - 1000.0) <= 50.0 else far
                c[o] += 1
                c["n"] += 1
                c["fired"] += fired
                if o in ("early", "late"):
                    wrong.append(f"{name} at {r:.0f} Hz: {o}")
            print(f"  {name} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
        for label, c in (("±2.5-5 %", near), ("farther", far)):
            cells = " | ".join(str(c[k]) for k in OUTCOMES)
            print(f"| {which} | {label} | {c['n']} | {cells} | {c['fired']} |", flush=True)
            total.update(c)
    cells = " | ".join(str(total[k]) for k in OUTCOMES)
    print(f"| all | | {total['n']} | {cells} | {total['fired']} |")
    for w in wrong:
        print(f"silently wrong: {w}")


def run_drive(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    tab: Counter[str] = Counter()
    wrong: list[str] = []
    for i in range(n):
        arm = int(rng.integers(1, 10_000))
        kind = dv.KINDS[int(rng.integers(len(dv.KINDS)))]
        drive_db = float(rng.uniform(-10.0, 10.0))
        jitter_us = float(rng.uniform(2.0, 40.0))
        rate = float(rng.uniform(950.0, 1050.0))
        rec_seed = int(rng.integers(10_000))
        try:
            tu = tune(dv.render(dv.tuning_scene(dv.Arm(arm, kind), drive_db)), SR, 2.0)
        except TuningError:
            tab["refused"] += 1
            continue
        scene = dv.Scene(
            arm=dv.Arm(arm, kind),
            rate=rate,
            stop_at=1.6,
            dur=2.5,
            drive_db=drive_db,
            jitter_us=jitter_us,
            seed=rec_seed,
        )
        o = outcome(tu, dv.render(scene), 1.6)
        tab[o] += 1
        if o in ("early", "late"):
            wrong.append(f"arm {arm} {kind}, drive {drive_db:+.1f} dB, jitter {jitter_us:.1f} µs, {rate:.1f} Hz: {o}")
        if (i + 1) % 20 == 0:
            print(f"  drive draws: {i + 1}/{n}", file=sys.stderr, flush=True)
    print(
        f"seventh generator, {n} random arms at 950-1050 Hz (seed {seed}): "
        + ", ".join(f"{k} {tab[k]}" for k in (*OUTCOMES, "refused"))
    )
    for w in wrong:
        print(f"silently wrong: {w}")


def main() -> None:
    """As ``make bench`` runs it: every set, and 60 drive draws."""
    run_sets(list(SETS))
    run_drive(60, 1)


def _cli() -> None:
    import argparse

    ap = argparse.ArgumentParser(
        description="The audio limit switch away from its tuning's step rate (module docstring)."
    )
    ap.add_argument("--sets", default=",".join(SETS), help=f"comma-separated: {', '.join(SETS)}, or 'none'")
    ap.add_argument("--drive", type=int, default=0, help="also draw this many random arms of the seventh generator")
    ap.add_argument("--seed", type=int, default=1, help="seed of the drive draws")
    ap.add_argument("--rates", help="comma-separated step rates of the test recordings, Hz (default: 900-1100)")
    ap.add_argument(
        "--commanded",
        action="store_true",
        help="tell the detector the commanded rate, as a traverse and listen --rate do",
    )
    ap.add_argument(
        "--stop-scale",
        choices=bm.STOP_SCALES,
        default="recording",
        help="the beams' stop loudness: scaled to each recording's stepping (default) or fixed per arm",
    )
    args = ap.parse_args()
    sets = [] if args.sets == "none" else [s.strip() for s in args.sets.split(",") if s.strip()]
    rates = tuple(float(r) for r in args.rates.split(",")) if args.rates else RATES_HZ
    if sets:
        run_sets(sets, rates, args.commanded, args.stop_scale)
    if args.drive > 0:
        run_drive(args.drive, args.seed)


if __name__ == "__main__":
    _cli()
