"""True stops under the hour's speech and music, stepped at and off the tuning's rate: the first event counted.

``bench_audio_hour.py`` counts false stops over an hour of stepping under speech, music and a radio;
this counts the other side (issue 35 item 6, "no stop missed"): a true stop heard under the same
sources. Per development arm (the tenth generator's arms 1-3, ``tests/support/fan_sound.py``; never
the hour's joints 4-8) the tuning is made from the arm's tuning scene (1000 Hz), then the arm steps
at a rate into its stop at 12 s (2 s of the stop after it), with the hour's "speech over the radio"
or "music" (``tests/support/hour_sound.py``) added at -3 or +3 dB to the stepping's RMS. The
confirming detector is told the rate (``reset(step_rate_hz=...)``): 1000 (the tuning's), 950, 1050,
1100 and 1200 Hz; and untold at 1000 Hz. The first event at or after the stop (less 25 ms) is
counted as ``bench_audio.py --onset`` counts it:

* **right**: its onset within 25 ms of the stop, not flagged;
* **flagged**: ``onset_uncertain`` (a traverse refuses it: never a wrong count);
* **early** / **late**: more than 25 ms off, not flagged: a silently wrong count;
* **missed**: no event at or after the stop.

The first event of the run (what a traverse counts to; an event before the stop is early or flagged)
and the first event at or after the stop are both tabled; events before the stop (false stops in the
stepping) are counted beside them (counted / flagged).
``--details`` prints per run what the confirming detector noted within 2 s of the stop (fires
rejected, judged on the step clock, found inside a window, the stepping stopping), to say which
stage held a stop that was missed or late.

A separate bench, not a ``--stops`` mode of ``bench_audio_hour.py``: that one streams ten-minute
recordings of the hour's joints (whose joints 4-8 are held out) and counts fires; this renders
14 s recordings of another generator's arms and counts one onset each, as ``bench_audio.py --onset``.

Run: ``nice .venv/bin/python benchmarks/bench_audio_stops_noise.py`` (72 runs, a few minutes on a
loaded core); ``--arms 1 --rates 1200 --details`` for one case.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # the generators

from fan_sound import SR, Arm, render, tuning_scene  # noqa: E402
from noise_bench import STOP_S, recording  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuning import tune  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402

#: an onset within this of the stop is right, s (as ``bench_audio.py``'s ``TOL_S``)
TOL_S = 0.025
#: the development arms (the tenth generator's)
ARMS = (1, 2, 3)
#: the rates stepped, Hz, and whether the detector is told them (the tuning's rate: 1000 Hz)
RATES: tuple[tuple[float, bool], ...] = (
    (1000.0, True),
    (950.0, True),
    (1050.0, True),
    (1100.0, True),
    (1200.0, True),
    (1000.0, False),
)
SOURCES = ("speech over the radio", "music")
LEVELS_DB = (-3.0, 3.0)
OUTCOMES = ("right", "flagged", "early", "late", "missed")


def judged(e: StopEvent | None) -> str:
    """One event judged against the stop (None: missed)."""
    if e is None:
        return "missed"
    err = e.onset_s - STOP_S
    return "flagged" if e.onset_uncertain else "early" if err < -TOL_S else "late" if err > TOL_S else "right"


def outcome(events: list[StopEvent]) -> tuple[str, str, float, int, int]:
    """The first event judged (as ``bench_audio.py --onset``: what a traverse counts to), the first at the stop
    judged, its onset error (s; NaN: none), and the counted / flagged before the stop."""
    before = [e for e in events if e.onset_s < STOP_S - TOL_S]
    at = [e for e in events if e.onset_s >= STOP_S - TOL_S]
    counted = sum(not e.onset_uncertain for e in before)
    err = at[0].onset_s - STOP_S if at else float("nan")
    return (judged(events[0] if events else None), judged(at[0] if at else None), err, counted, len(before) - counted)


def details(det: ConfirmedStopDetector, times: tuple[float, ...] | list[float] = (STOP_S,)) -> list[str]:
    """What the confirming detector noted from 0.5 s before to 2 s after the stop, or any of ``times`` (its log)."""
    log = det.log

    def near(t: float) -> bool:
        return any(u - 0.5 <= t <= u + 2.0 for u in times)

    out = [
        f"rejected fire at {e.detected_at_s:.3f} s (onset {e.onset_s:.3f})"
        for e in log.rejected
        if near(e.detected_at_s)
    ]
    out += [f"clocked at {t:.3f} s: {c}" for t, c in log.clocked if near(t)]
    out += [f"stepping stopped at {t:.3f} s: {w}" for t, w in log.stopped if near(t)]
    out += [f"inside at {t:.3f} s: onset {o:.3f}, spread {s:.3f}" for t, o, s in log.inside if near(t)]
    out += [f"onset doubted at {t:.3f} s: {w}" for t, w in log.onset if near(t)]
    out += [f"late path swallowed {e.detected_at_s:.3f} s" for e in log.late_swallowed if near(e.detected_at_s)]
    return out


def run(tu: Tuning, y: np.ndarray, told_hz: float | None) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    det = ConfirmedStopDetector(detector_for(tu))
    det.reset(0.0, step_rate_hz=told_hz)
    return det.feed(y) + det.finish(), det


def table(counts: Counter[tuple[str, str]], title: str) -> None:
    labels = list(dict.fromkeys(k for k, _ in counts))
    print(f"\n{title}\n| rate | " + " | ".join(OUTCOMES) + " |\n| --- |" + " --- |" * len(OUTCOMES))
    for label in labels:
        print(f"| {label} | " + " | ".join(str(counts[label, o]) for o in OUTCOMES) + " |")
    print("| all | " + " | ".join(str(sum(counts[k, o] for k in labels)) for o in OUTCOMES) + " |")


def main(arms: tuple[int, ...], rates: tuple[tuple[float, bool], ...], show: bool) -> Counter[tuple[str, str]]:
    first: Counter[tuple[str, str]] = Counter()
    at: Counter[tuple[str, str]] = Counter()
    before: Counter[str] = Counter()
    for arm in arms:
        tu = tune(render(tuning_scene(Arm(arm))), SR, 2.0)
        for rate, told in rates:
            label = f"{rate:.0f} told" if told else f"{rate:.0f} untold"
            for kind in SOURCES:
                for db in LEVELS_DB:
                    ev, det = run(tu, recording(arm, rate, kind, db), rate if told else None)
                    what, what_at, err, n_counted, n_flagged = outcome(ev)
                    first[label, what] += 1
                    at[label, what_at] += 1
                    before["counted"] += n_counted
                    before["flagged"] += n_flagged
                    e = "" if err != err else f" {err * 1000:+.0f} ms"
                    print(
                        f"arm {arm} {label} {kind} {db:+.0f} dB: first {what}; at the stop {what_at}{e};"
                        f" before {n_counted}/{n_flagged}",
                        flush=True,
                    )
                    if show:
                        print("    " + "\n    ".join(details(det) or ["(nothing noted near the stop)"]))
    table(first, "the first event (what a traverse counts to; as bench_audio.py --onset)")
    table(at, "the first event at or after the stop (less 25 ms)")
    print(f"events before the stop: {before['counted']} counted, {before['flagged']} flagged")
    return first


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="True stops under the hour's speech and music (docstring).")
    ap.add_argument("--arms", default="1,2,3", help="the tenth generator's arms (development: 1-3)")
    ap.add_argument(
        "--rates", default=None, help="stepped rates told, Hz, comma-separated (default: all, and untold 1000)"
    )
    ap.add_argument("--details", action="store_true", help="what the detector noted near each stop")
    a = ap.parse_args()
    chosen = tuple(int(s) for s in a.arms.split(","))
    if any(arm not in ARMS for arm in chosen):
        ap.error("development arms only: 1, 2, 3")
    rs = RATES if a.rates is None else tuple((float(s), True) for s in a.rates.split(","))
    main(chosen, rs, a.details)
