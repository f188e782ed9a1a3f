"""The stop's signature on the step clock's lines, against the present rule, side by side on draws it was not made on.

``stickslip.audio.confirm.clocked`` asks a fire that persisted to show the stop's signature
on the step clock's harmonic lines (music, a radio, a fan add power between them, a stop
changes the joint's own clicks). Its threshold was set on the hour generator's joint 3 (its
own draw, seed 3) and the tenth generator's test draws; here both detectors - the present
rule (``ConfirmParams(clocked=None)``) and the check - hear the same samples:

* **the hour** (``tests/support/hour_sound.py``): per joint (arms 1-3 of the tenth
  generator), ``--minutes`` of stepping at 1000 Hz (told) under speech, music and a radio,
  no stop, on other draws (seed ``arm + 1000 k``, k = 1 .. ``--seeds``): false stops
  counted / flagged;
* **the tenth generator** (``tests/test_audio_fan.py``'s conditions, arms 1-8, draws moved
  by ``1000 k``, k = 0 .. ``--seeds``): a fan before the stop (2 draws per arm), two pauses
  and no stop, a test 12-20 dB louder, another arm in bursts in the test, a test 20 %
  off the tuning's rate (told): the first event judged as ``bench_audio_tenth.py`` does;
* **the cost**: the confirming detector in 1024-sample blocks over the tenth generator's 16
  recordings of a stop (one decision each), with and without the check, in turns (A B A
  B): the ratio of the CPU times (``time.process_time``: the machine may be shared).

Run: ``.venv/bin/python benchmarks/bench_audio_clocked.py --minutes 10 --seeds 2``
(several minutes on a shared machine). ``--present wide-comb`` takes for the present rule the
check as it was before it read the lines in step (``combs=(0.004,)``, nothing kept, one span),
``--present in-step`` the check before it kept stepping and read a long window in spans;
``--hour-only`` hears only the hour.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # the tenth generator's judge
sys.path.insert(0, str(HERE.parent / "tests"))  # the conditions (test_audio_fan.py)
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # the generators

from bench_audio_tenth import judge  # noqa: E402
from fan_sound import Arm, Scene, render  # noqa: E402
from hour_sound import Hour, spans, stream  # noqa: E402

import test_audio_fan as tf  # noqa: E402
from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams  # noqa: E402
from stickslip.audio.confirm.clocked import ClockedParams  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402

RULES = {"present": ConfirmParams(clocked=None), "clocked": ConfirmParams()}


def _pair(tu: Tuning, rate: float) -> dict[str, ConfirmedStopDetector]:
    dets = {k: ConfirmedStopDetector(detector_for(tu), params=p) for k, p in RULES.items()}
    for d in dets.values():
        d.reset(0.0, step_rate_hz=rate)
    return dets


def _heard(tu: Tuning, y: np.ndarray, rate: float = 1000.0) -> dict[str, list[StopEvent]]:
    return {k: d.feed(y) + d.finish() for k, d in _pair(tu, rate).items()}


def hour(arm: int, seed: int, minutes: float) -> dict[str, tuple[int, int, list[str]]]:
    """Per rule: false stops counted, flagged, and where (kind of sound, level)."""
    h = Hour(Arm(arm), dur=60.0 * minutes, seed=seed)
    dets = _pair(tf._tuning(arm), h.rate)
    got: dict[str, list[StopEvent]] = {k: [] for k in dets}
    for block in stream(h):
        for k, d in dets.items():
            got[k] += d.feed(block)
    sched = spans(h)
    out = {}
    for k, d in dets.items():
        events = got[k] + d.finish()
        where = [next(f"{s[2]} {s[3]:+.1f} dB" for s in sched if s[0] <= e.onset_s < s[1]) for e in events]
        counted = sum(not e.onset_uncertain for e in events)
        out[k] = (counted, len(events) - counted, where)
    return out


def tenth(k: int) -> dict[str, dict[str, list[str]]]:
    """Per rule, per condition: the first event's outcome per arm on the ``k``-th draw (0: the tests' own)."""
    out: dict[str, dict[str, list[str]]] = {r: {} for r in RULES}

    def put(cond: str, got: dict[str, list[StopEvent]], **kw: float) -> None:
        for r, events in got.items():
            res = ("false" if events else "quiet") if cond == "pauses" else judge(events, **kw)
            out[r].setdefault(cond, []).append(res)

    for arm in tf.ARMS:
        tu = tf._tuning(arm)
        for d in (0, 1):
            put("fan", _heard(tu, render(tf._fan_draw(arm, d, k))))
        put("pauses", _heard(tu, render(tf._pause_draw(arm, k))))
        scene, gain_db = tf._louder_draw(arm, k)
        put(
            "louder",
            _heard(tu, (render(scene) * np.float32(10 ** (gain_db / 20))).astype(np.float32)),
            heard_within_s=0.05,
        )
        y = render(Scene(Arm(arm), stop_at=tf.STOP_S, dur=3.4, seed=300 + arm + 1000 * k))
        put("bursts test", _heard(tu, (y + tf._bursts(arm, 3.4, 600 + arm + 1000 * k)).astype(np.float32)))
        rs = tf._rate_draw(arm, k)
        put("rate 20 % off", _heard(tu, render(rs), rs.rate))
    return out


def cost(turns: int = 7) -> float:
    """CPU time with the check over without it: the confirming detector in 1024-sample blocks over the tenth
    generator's 16 recordings of a stop (quiet and under a fan; one decision each, the same events), in turns."""
    recs = []
    for arm in tf.ARMS:
        recs.append((tf._tuning(arm), render(Scene(Arm(arm), stop_at=tf.STOP_S, dur=3.4, seed=300 + arm))))
        recs.append((tf._tuning(arm), render(tf._fan_draw(arm, 0))))
    spent = {k: 0.0 for k in RULES}
    for _ in range(turns):
        for k, p in RULES.items():
            t = time.process_time()
            for tu, y in recs:
                d = ConfirmedStopDetector(detector_for(tu), params=p)
                d.reset(0.0, step_rate_hz=1000.0)
                for i in range(0, y.size, 1024):
                    d.feed(y[i : i + 1024])
                d.finish()
            spent[k] += time.process_time() - t
    return spent["clocked"] / spent["present"]


def _counts(results: list[str]) -> str:
    return ", ".join(f"{n} {what}" for what, n in sorted(Counter(results).items()))


def main(minutes: float, seeds: int, arms: tuple[int, ...], hour_only: bool = False) -> None:
    print(f"the hour on other draws: {minutes:g} min per joint, false stops counted / flagged")
    print("| joint | seed | present rule | with the check |")
    print("| --- | --- | --- | --- |")
    for k in range(1, seeds + 1):
        for arm in arms:
            got = hour(arm, arm + 1000 * k, minutes)
            cells = [f"{c} / {f}" + (f" ({'; '.join(sorted(set(w)))})" if w else "") for c, f, w in got.values()]
            print(f"| {arm} | {arm + 1000 * k} | " + " | ".join(cells) + " |", flush=True)
    if hour_only:
        return
    print("\nthe tenth generator, arms 1-8 (first event; pauses: quiet / false)")
    print("| draw | condition | present rule | with the check |")
    print("| --- | --- | --- | --- |")
    for k in range(0, seeds + 1):
        got = tenth(k)
        for cond in got["present"]:
            a, b = got["present"][cond], got["clocked"][cond]
            moved = [
                f"arm {1 + i // (2 if cond == 'fan' else 1)}: {x} -> {y}"
                for i, (x, y) in enumerate(zip(a, b, strict=True))
                if x != y
            ]
            note = f" ({'; '.join(moved)})" if moved else ""
            print(f"| {'own' if k == 0 else f'+{1000 * k}'} | {cond} | {_counts(a)} | {_counts(b)}{note} |", flush=True)
    print(f"\ncost: CPU time with the check / without it, 16 recordings of a stop in 1024-sample blocks: {cost():.3f}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="The step clock's check against the present rule (docstring).")
    ap.add_argument("--minutes", type=float, default=10.0, help="minutes of the hour per joint and draw")
    ap.add_argument("--seeds", type=int, default=2, help="other draws (each seed + 1000 k)")
    ap.add_argument("--arms", default="1,2,3", help="joints of the hour (arms of the tenth generator)")
    ap.add_argument(
        "--present", choices=("none", "wide-comb", "in-step"), default="none", help="the present rule's check"
    )
    ap.add_argument("--hour-only", action="store_true", help="hear only the hour")
    a = ap.parse_args()
    if a.present == "wide-comb":
        RULES["present"] = ConfirmParams(clocked=ClockedParams(combs=(0.004,), kept_age_s=0.0, window_pieces=1))
    if a.present == "in-step":
        RULES["present"] = ConfirmParams(clocked=ClockedParams(kept_age_s=0.0, window_pieces=1))
    main(a.minutes, a.seeds, tuple(int(x) for x in a.arms.split(",")), a.hour_only)
