"""The tenth generator's conditions on other draws: a fan, pauses, a louder test, an instrument in bursts.

``tests/test_audio_fan.py`` holds one draw of each condition per arm (arms 1-8 of the tenth
generator, ``tests/support/fan_sound.py``, written before the detector was changed for them).
Here every draw is made again with its seeds moved by ``1000 x k`` (k = 1 .. ``--seeds``), an
independent battery per k, and the first confirmed event (the commanded 1000 Hz told) counted:

* **right**: the stop within 25 ms, not flagged (and, for the louder test, heard within 50 ms);
* **flagged**: ``onset_uncertain`` (a traverse refuses it: never a wrong count);
* **early** / **late**: more than 25 ms off (or heard late), not flagged: a wrong count;
* **missed**: no event; **refused**: the tuning refused its recording (an instrument in the training);
  the tuning is told the commanded rate, as a traverse's recording tells it (``--untold``: not, as before);
* for the pauses without a stop: **quiet** (no event) or **false** (any event).

Run: ``.venv/bin/python benchmarks/bench_audio_tenth.py --seeds 3`` (a few minutes per draw on 2 cores);
``--kept-age 0 --window-pieces 1`` hears every condition with the clocked check's variant
(``ClockedParams.kept_age_s``, ``window_pieces``; these two: the check of the round before) instead of the default;
``--min-affirm inf --onset-read-s 0`` with the lines in phase as a veto only (before they affirmed a fire the levels
hold but not hot, and were read from each stop's onset).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))  # the conditions (test_audio_fan.py)
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # the generator

from fan_sound import SR, Arm, Scene, render, tuning_scene  # noqa: E402

import test_audio_fan as tf  # noqa: E402
from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams  # noqa: E402
from stickslip.audio.confirm.clocked import ClockedParams  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuning import TuningError, tune  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402

#: the step rate the tuning is told, Hz (None: not told, ``--untold``)
TOLD: list[float | None] = [1000.0]


def judge(events: list[StopEvent], heard_within_s: float | None = None) -> str:
    if not events:
        return "missed"
    e = events[0]
    if e.onset_uncertain:
        return "flagged"
    err = e.onset_s - tf.STOP_S
    if err < -tf.TOL_S:
        return "early"
    if err > tf.TOL_S or (heard_within_s is not None and e.detected_at_s - tf.STOP_S > heard_within_s):
        return "late"
    return "right"


def draw(k: int) -> dict[str, list[str]]:
    """Every condition's outcome per arm on the ``k``-th other draw (0: the tests' own)."""
    out: dict[str, list[str]] = {"fan": [], "pauses": [], "louder": [], "bursts test": [], "bursts training": []}
    out["bursts both"] = []
    for arm in tf.ARMS:
        tu = tf._tuning(arm)
        for d in (0, 1):
            out["fan"].append(judge(tf._events(tu, render(tf._fan_draw(arm, d, k)))))
        out["pauses"].append("false" if tf._events(tu, render(tf._pause_draw(arm, k))) else "quiet")
        scene, gain_db = tf._louder_draw(arm, k)
        y = (render(scene) * np.float32(10 ** (gain_db / 20))).astype(np.float32)
        out["louder"].append(judge(tf._events(tu, y), heard_within_s=0.050))
        x0 = render(tuning_scene(Arm(arm)))
        y0 = render(Scene(Arm(arm), stop_at=tf.STOP_S, dur=3.4, seed=300 + arm + 1000 * k))
        bx = tf._bursts(arm, 3.2, 500 + arm + 1000 * k)
        by = tf._bursts(arm, 3.4, 600 + arm + 1000 * k)
        for where, x, y in (("test", None, y0 + by), ("training", x0 + bx, y0), ("both", x0 + bx, y0 + by)):
            try:
                t = tu if x is None else tune(np.asarray(x, dtype=np.float32), SR, 2.0, step_rate_hz=TOLD[0])
            except TuningError:
                out[f"bursts {where}"].append("refused")
                continue
            out[f"bursts {where}"].append(judge(tf._events(t, np.asarray(y, dtype=np.float32))))
    return out


def main(seeds: int = 2) -> None:
    print(f"the tenth generator's conditions on {seeds} other draws (arms {tf.ARMS.start}-{tf.ARMS.stop - 1})")
    for k in range(0, seeds + 1):
        t = time.perf_counter()
        out = draw(k)
        label = "the tests' own draw" if k == 0 else f"seeds + {1000 * k}"
        print(f"{label} ({time.perf_counter() - t:.0f} s):")
        for cond, results in out.items():
            counts = ", ".join(f"{n} {what}" for what, n in sorted(Counter(results).items()))
            bad = [
                f"arm {1 + i // (2 if cond == 'fan' else 1)}: {r}"
                for i, r in enumerate(results)
                if r not in ("right", "quiet", "refused")
            ]
            print(f"  {cond:16s} {counts}" + (f"  ({'; '.join(bad)})" if bad else ""))


def with_clocked(p: ClockedParams) -> None:
    """Every condition heard with the clocked check's parameters ``p`` (as a traverse tells the rate)."""

    def events(tu: Tuning, y: np.ndarray, rate_hz: float = 1000.0) -> list[StopEvent]:
        det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=p))
        det.reset(0.0, step_rate_hz=rate_hz)
        return det.feed(y) + det.finish()

    tf._events = events


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="The tenth generator's conditions on other draws (docstring).")
    ap.add_argument("--seeds", type=int, default=2, help="how many other draws (each seed + 1000 k)")
    ap.add_argument("--kept-age", type=float, default=None, help="the clocked check's kept_age_s, s")
    ap.add_argument("--window-pieces", type=int, default=None, help="the clocked check's window_pieces")
    ap.add_argument("--min-affirm", type=float, default=None, help="the clocked check's min_affirm (inf: none)")
    ap.add_argument("--onset-read-s", type=float, default=None, help="the clocked check's onset_read_s, s (0: none)")
    ap.add_argument("--untold", action="store_true", help="the tuning not told the commanded rate (as before)")
    a = ap.parse_args()
    if a.untold:
        TOLD[0] = None
    given = {
        "kept_age_s": a.kept_age,
        "window_pieces": a.window_pieces,
        "min_affirm": a.min_affirm,
        "onset_read_s": a.onset_read_s,
    }
    if any(v is not None for v in given.values()):
        with_clocked(ClockedParams(**{k: v for k, v in given.items() if v is not None}))
    main(a.seeds)
