"""An hour of stepping with speech, music and a radio and no stop, per joint: the false stops a traverse would hear.

The eleventh generator (``tests/support/hour_sound.py``), independent of the detector's
development: each joint (arms of the tenth generator, ``tests/support/fan_sound.py``) tuned on
its own quiet 1000 Hz recording, then an hour of stepping at the commanded rate (told to the
detector, as a traverse tells it) rendered as a stream of 1 s blocks and heard by the confirming
detector block by block, without a restart: spans of 15-90 s of nothing added, speech, music,
a radio, or speech over the radio, at -12 to +3 dB re the stepping. Every confirmed event is a
false stop; a flagged one (``onset_uncertain``) a traverse refuses, an unflagged one it would
count to. The table gives, per joint and per kind of sound, the minutes heard and the false
stops (unflagged / flagged); then the events.

``tests/test_audio_hour.py`` runs a minute per joint with shorter spans (the slow tier).

Run: ``.venv/bin/python benchmarks/bench_audio_hour.py`` (arms 1-3, an hour each: several
minutes per joint on a shared machine, the generator about as costly as the detector);
``--minutes 10`` for a shorter stretch, ``--arms 1,2,3,4,5,6,7,8`` for every arm of the generator,
``--rate 1150`` to step (and tell) another rate than the tuning's, ``--details`` to print under each
false stop what the confirming detector noted (``ConfirmLog``): the clocked check's verdict, the
onset's doubt, the rejected fires before it. ``docs/audio-log.md`` ("Diagnosis of the hour's false
stops") reads those lines. ``--variants in-step,default`` hears the same samples with
each variant of the clocked check (``VARIANTS``) side by side, one table each.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # the generators

from fan_sound import SR, Arm, render, tuning_scene  # noqa: E402
from hour_sound import KINDS, Hour, spans, stream  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams  # noqa: E402
from stickslip.audio.confirm.clocked import ClockedParams  # noqa: E402
from stickslip.audio.confirm.detector import ConfirmLog  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuning import tune  # noqa: E402


def details(e: StopEvent, log: ConfirmLog) -> str:
    """What the confirming detector noted about the event ``e``: the clocked check, the onset, the fires before."""
    got = [g for t, g in log.clocked if t == e.detected_at_s]
    clocked = (
        f"a_L {got[0].a:.2f} on {got[0].bands} sub-bands at {got[0].rate_hz:.2f} Hz"
        + (f", against the stepping kept {got[0].kept_s:.2f} s before" if got[0].kept_s == got[0].kept_s else "")
        if got
        else "not judged (reference stop-like, too little heard or rate off)"
    )
    doubt = [why for t, why in log.onset if t == e.detected_at_s]
    before = [r.detected_at_s for r in log.rejected if e.detected_at_s - 30.0 < r.detected_at_s < e.detected_at_s]
    last = f", the last {e.detected_at_s - before[-1]:.2f} s before" if before else ""
    return (
        f"      stop-likeness {e.level_db:.3f}, window {e.confirmed_s or 0.0:.2f} s; onset doubted:"
        f" {doubt[0] if doubt else 'no'}\n      clocked check: {clocked}\n"
        f"      {len(before)} fires rejected in the 30 s before{last}"
    )


#: the clocked check's variants ``--variants`` compares: its lines read on the 0.4 % comb only (two rounds back); read
#: in step, a reference stop-like to the levels giving no verdict and a window read on its first span (the round
#: before); the latest stepping kept no longer than 10 s, 30 s or 120 s before taken for such a reference; a longer
#: window read in four spans, the median kept; both (the default)
ROUND_BEFORE = ClockedParams(kept_age_s=0.0, window_pieces=1)
VARIANTS: dict[str, ClockedParams | None] = {
    "before": replace(ROUND_BEFORE, combs=(0.004,)),
    "in-step": ROUND_BEFORE,
    "kept10": replace(ROUND_BEFORE, kept_age_s=10.0),
    "kept30": replace(ROUND_BEFORE, kept_age_s=30.0),
    "kept120": replace(ROUND_BEFORE, kept_age_s=120.0),
    "pieces": replace(ROUND_BEFORE, window_pieces=4),
    "default": ClockedParams(),
    "off": None,
}


def hour(
    arm: int, minutes: float, rate: float, detail: bool = False, variants: tuple[str, ...] = ("default",)
) -> dict[str, tuple[dict[str, list[float]], list[str]]]:
    """Per variant: per kind [seconds, unflagged, flagged]; and one line per event (two with ``detail``)."""
    tu = tune(render(tuning_scene(Arm(arm))), SR, 2.0)
    h = Hour(Arm(arm), rate=rate, dur=60.0 * minutes, seed=arm)
    dets = {v: ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=VARIANTS[v])) for v in variants}
    heard: dict[str, list[StopEvent]] = {v: [] for v in variants}
    for d in dets.values():
        d.reset(0.0, step_rate_hz=rate)
    for block in stream(h):
        for v, d in dets.items():
            heard[v] += d.feed(block)
    return {v: _table(spans(h), heard[v] + d.finish(), d.log, detail) for v, d in dets.items()}


def _table(
    sched: list[tuple[float, float, str, float]], events: list[StopEvent], log: ConfirmLog, detail: bool
) -> tuple[dict[str, list[float]], list[str]]:
    per = {k: [0.0, 0.0, 0.0] for k in KINDS}
    for t0, t1, kind, _ in sched:
        per[kind][0] += t1 - t0
    lines = []
    for e in events:
        t0, t1, kind, db = next(s for s in sched if s[0] <= e.onset_s < s[1])
        per[kind][2 if e.onset_uncertain else 1] += 1
        lines.append(
            f"    {e.onset_s:8.2f} s  {'flagged' if e.onset_uncertain else 'COUNTED'}  {kind} at {db:+.1f} dB"
            f" (its span {t0:.1f}-{t1:.1f} s)"
        )
        if detail:
            lines.append(details(e, log))
    return per, lines


def main(
    arms: tuple[int, ...] = (1, 2, 3),
    minutes: float = 60.0,
    rate: float = 1000.0,
    detail: bool = False,
    variants: tuple[str, ...] = ("default",),
) -> None:
    print(
        f"{minutes:g} min of stepping at {rate:g} Hz (told) with speech, music and a radio, no stop: "
        "false stops (unflagged, a wrong count / flagged, refused)"
    )
    print("| joint | clocked check | " + " | ".join(KINDS) + " | all | s |")
    print("| --- " * (len(KINDS) + 4) + "|")
    for arm in arms:
        t = time.perf_counter()
        got = hour(arm, minutes, rate, detail, variants)
        for v, (per, lines) in got.items():
            cells = [f"{int(u)} / {int(f)} in {s / 60:.0f} min" for s, u, f in per.values()]
            u_all, f_all = sum(x[1] for x in per.values()), sum(x[2] for x in per.values())
            print(
                f"| {arm} | {v} | " + " | ".join(cells) + f" | {int(u_all)} / {int(f_all)} |"
                f" {time.perf_counter() - t:.0f} |"
            )
            for line in lines:
                print(line)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="An hour of stepping under speech, music and a radio (docstring).")
    ap.add_argument("--arms", default="1,2,3", help="arms of the tenth generator, comma-separated")
    ap.add_argument("--minutes", type=float, default=60.0, help="minutes of stepping per joint")
    ap.add_argument("--rate", type=float, default=1000.0, help="the step rate, Hz (told to the detector)")
    ap.add_argument("--details", action="store_true", help="what the detector noted about each false stop")
    ap.add_argument("--variants", default="default", help=f"the clocked check's variants: {', '.join(VARIANTS)}")
    a = ap.parse_args()
    vs = tuple(a.variants.split(","))
    if not set(vs) <= set(VARIANTS):
        ap.error(f"--variants: one of {', '.join(VARIANTS)}, comma-separated (got {a.variants})")
    main(tuple(int(x) for x in a.arms.split(",")), a.minutes, a.rate, a.details, vs)
