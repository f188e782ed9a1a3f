"""The stepping's lines model (``ClockedParams.lines_model``) off against on, on generators it was not built on.

The model was developed on the hour generator (``tests/support/hour_sound.py``, joints 1-3) and the tenth
generator's arms under the hour's noises (``bench_audio_stops_noise.py``); ``bench_audio_rates.py``'s recordings
are 3 s long, so it is never ready there. This bench asks it of other generators, on recordings long enough for it
to be ready: the fifth (``arrival_sound.py``: the stop arriving over a few steps, in a room; its clock jittered
0.4 % per step as the hour's, and ``arrival-1%`` at its own default 1 %), the seventh (``drive_sound.py``: the
piezo's drive heard through the stop, a crystal clock) and the fourth (``modal_sound.py``: 2 % clock jitter). The
model accepts a span only where its lines hold ``model_min_share`` (0.9) of their power in phase: at 2 % jitter
none does (never ready: off equals on), at 1 % some clean runs do; added sound lowers the share too (each run
prints the model's weight at the end and the fires it read).
Each arm is tuned on its generator's tuning recording at 1000 Hz, then steps at a told rate (900, 950, 1100, 1200
Hz) for :data:`STOP_S` s into its stop (2 s of the stop after it), clean or with the hour's "music" (-3 dB) or
"speech over the radio" (+3 dB) added re the stepping's RMS. The same samples are heard by two confirming
detectors in one process: the switch off (``ClockedParams(lines_model=False)``) and on (the default); ``--switch
model_unjudged`` compares that switch instead (a stop the model could have judged and did not, flagged), ``--switch
model_expect`` the model's span gate expecting the jittered clock's loss (``arrival-2%``: the fifth
generator at 2 % jitter), ``--switch model_in_step`` the fire the model let through with its lines out of step
(flagged; off: 0), ``--switch model_edge_s`` a stop found inside a vetoed window whose onset fit split at the
fitted stretch's end (dropped; off: 0), ``--switch model_in_step_hold_z`` a fire flagged out of step whose lines
stay departed past its window counted (off: 0), ``--switch model_rejected`` a fire the levels rejected whose window
departs from the model in every span and past it, emitted flagged, ``--switch model_refired`` the same reading of a
window cut short by a fire inside it, ``--switch model_onset`` an onset the model's lines place elsewhere, flagged,
``--switch model_min_bands`` a veto on one locked sub-band, flagged instead (off: 0),
``--switch told_held_tol`` the lines read at the told rate once the clock was heard there (off: 0),
``--switch model_rejected_early`` a rejected window read so before the model is ready, against the spans before it,
``--switch onset_short_span`` a stop whose fire's reference the stream's start cut short (under
``SyncParams.span_s``), flagged (off: under ``min_s``).

The first event at or after the stop (less 25 ms) is counted as ``bench_audio_stops_noise.py`` counts it: right
(within 25 ms, not flagged), flagged (``onset_uncertain``), early / late (more than 25 ms off, not flagged: a
silently wrong count), missed (none); events before the stop are false stops (counted / flagged). Every run whose
events differ between off and on is printed with both event lists and what each detector noted near them.

Run: ``nice .venv/bin/python benchmarks/bench_audio_lines_model.py`` (all; tens of minutes on a loaded core);
``--gens drive --rates 1200 --noises clean`` for one case.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # the generators

import arrival_sound  # noqa: E402
import drive_sound  # noqa: E402
import modal_sound  # noqa: E402
from bench_audio_stops_noise import details  # noqa: E402  (the detector's log near given times)
from hour_sound import over_stepping  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector  # noqa: E402
from stickslip.audio.confirm.clocked import ClockedParams  # noqa: E402
from stickslip.audio.confirm.detector import ConfirmParams  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuning import tune  # noqa: E402

SR = 48_000
#: the stop, s into the recording (the model needs 4 clean spans and 2.5 s of lag to be ready)
STOP_S = 20.0
#: an onset within this of the stop is right, s
TOL_S = 0.025
RATES = (900.0, 950.0, 1100.0, 1200.0)
#: added sound: (the hour's source, level re the stepping's RMS, dB); "clean": none
NOISES: dict[str, tuple[str, float] | None] = {
    "clean": None,
    "music -3": ("music", -3.0),
    "speech over the radio +3": ("speech over the radio", 3.0),
}
OUTCOMES = ("right", "flagged", "early", "late", "missed")
#: the ``ClockedParams`` switch compared: off (the field False) against on (the default)
SWITCHES = (
    "lines_model",
    "model_unjudged",
    "model_expect",
    "model_in_step",
    "model_edge_s",
    "model_hold_s",
    "model_in_step_hold_z",
    "model_rejected",
    "model_refired",
    "model_onset",
    "model_min_bands",
    "told_held_tol",
    "model_rejected_early",
    "onset_short_span",
)


def switch(name: str) -> dict[str, ClockedParams]:
    """The two detectors' clocked parameters: ``name`` False (off) and True (on), the others their defaults
    (``model_in_step``, a share, ``model_edge_s``, ``model_hold_s``, s, ``model_in_step_hold_z``, spreads,
    ``told_held_tol``, a share, and ``model_min_bands``, sub-bands: 0 off, its default on)."""
    if name in ("model_in_step", "model_edge_s", "model_hold_s", "model_in_step_hold_z", "told_held_tol",
                "model_min_bands"):
        return {"off": replace(ClockedParams(), **{name: 0.0}), "on": ClockedParams()}
    return {"off": replace(ClockedParams(), **{name: False}), "on": replace(ClockedParams(), **{name: True})}


Render = Callable[[float, float | None, float, int], np.ndarray]  # rate, stop, dur, seed -> samples


def _arrival(seed: int, kind: str, jitter: float) -> Render:
    arm = arrival_sound.Arm(seed, kind)

    def r(rate: float, stop: float | None, dur: float, s: int) -> np.ndarray:
        if stop is not None and dur < 5.0:  # the tuning recording
            return arrival_sound.render(arrival_sound.tuning_scene(arm))
        return arrival_sound.render(
            arrival_sound.Scene(arm=arm, rate=rate, stop_at=stop, dur=dur, jitter=jitter, seed=s)
        )

    return r


def _drive(seed: int, kind: str) -> Render:
    arm = drive_sound.Arm(seed, kind)

    def r(rate: float, stop: float | None, dur: float, s: int) -> np.ndarray:
        if stop is not None and dur < 5.0:
            return drive_sound.render(drive_sound.tuning_scene(arm))
        return drive_sound.render(drive_sound.Scene(arm=arm, rate=rate, stop_at=stop, dur=dur, seed=s))

    return r


def _modal(seed: int, kind: str) -> Render:
    def r(rate: float, stop: float | None, dur: float, s: int) -> np.ndarray:
        snr = 35.0 if dur < 5.0 else 25.0
        return modal_sound.render(
            modal_sound.Scene(joint_seed=seed, kind=kind, stop_at=stop, dur=dur, rate=rate, snr_db=snr, seed=s)
        )

    return r


#: per generator, its arms: (label, renderer)
ARMS: dict[str, tuple[tuple[str, Render], ...]] = {
    "arrival": (("arm 1 stiff", _arrival(1, "stiff", 0.004)), ("arm 2 damped", _arrival(2, "damped", 0.004))),
    "arrival-1%": (("arm 1 stiff", _arrival(1, "stiff", 0.01)), ("arm 2 damped", _arrival(2, "damped", 0.01))),
    "arrival-2%": (("arm 1 stiff", _arrival(1, "stiff", 0.02)), ("arm 2 damped", _arrival(2, "damped", 0.02))),
    "drive": (("arm 1 blocked", _drive(1, "blocked")), ("arm 2 spectral", _drive(2, "spectral"))),
    "modal": (("joint 1 spectral", _modal(1, "spectral")), ("joint 2 duller", _modal(2, "duller"))),
}


def recording(render: Render, rate: float, noise: str, seed: int) -> np.ndarray:
    """The arm stepping at ``rate`` into its stop at :data:`STOP_S`, the noise added."""
    y = np.asarray(render(rate, STOP_S, STOP_S + 2.0, seed), dtype=np.float64)
    add = NOISES[noise]
    if add is not None:
        kind, db = add
        y = over_stepping(y, kind, db, np.random.default_rng(seed + int(db)), int(STOP_S * SR))
    return np.asarray(y, dtype=np.float32)


def judged(e: StopEvent | None) -> str:
    """One event judged against the stop (None: missed)."""
    if e is None:
        return "missed"
    err = e.onset_s - STOP_S
    return "flagged" if e.onset_uncertain else "early" if err < -TOL_S else "late" if err > TOL_S else "right"


def outcome(events: list[StopEvent]) -> tuple[str, int, int]:
    """The first event at the stop judged, and the counted / flagged before it."""
    before = [e for e in events if e.onset_s < STOP_S - TOL_S]
    at = [e for e in events if e.onset_s >= STOP_S - TOL_S]
    counted = sum(not e.onset_uncertain for e in before)
    return judged(at[0] if at else None), counted, len(before) - counted


def model_state(det: ConfirmedStopDetector) -> str:
    """What the stepping's lines model held at the end (weight, locked sub-bands) and the fires it read: when (s) and
    their lines' RMS off the model (``still_z``, spreads; under ``model_max_z`` = 3: vetoed)."""
    c = det.checks.clocked
    if c is None or c.model is None:
        return "model none"
    m = c.model
    reads = " ".join(
        f"{t:.2f}:{oc.still_z:.1f}"
        + (f" in step {oc.in_step:.2f}/{oc.model_share:.2f} {oc.added_db:+.1f} dB" if oc.in_step >= 0 else "")
        for t, oc in det.log.clocked
        if np.isfinite(oc.still_z)
    )
    held = f"model weight {m.weight:.1f}, {len(m.locked_bands())}/{len(m.bands)} sub-bands locked"
    return f"{held}; read (s:z) {reads or '-'}"


def _fmt(ev: list[StopEvent]) -> str:
    return ", ".join(f"{e.onset_s:.3f}{'?' if e.onset_uncertain else ''}" for e in ev) or "none"


def main(
    gens: tuple[str, ...], rates: tuple[float, ...], noises: tuple[str, ...], name: str = "lines_model"
) -> dict[str, Counter[str]]:
    tally: dict[str, Counter[str]] = {}
    for gen in gens:
        for label, render in ARMS[gen]:
            tu = tune(np.asarray(render(1000.0, 2.0, 3.5, 7), dtype=np.float32), SR, 2.0)
            for rate in rates:
                for i, noise in enumerate(noises):
                    y = recording(render, rate, noise, int(rate) * 10 + i + 5)
                    got = {}
                    for sw, cp in switch(name).items():
                        det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=cp))
                        det.reset(0.0, step_rate_hz=rate)
                        got[sw] = (det.feed(y) + det.finish(), det)
                    line = f"{gen} {label} {rate:.0f} told, {noise}:"
                    for sw, (ev, _) in got.items():
                        what, n_c, n_f = outcome(ev)
                        t = tally.setdefault(f"{gen} {rate:.0f} {sw}", Counter())
                        t[what] += 1
                        t["counted"] += n_c
                        t["flagged before"] += n_f
                        line += f" {sw} {what} before {n_c}/{n_f};"
                    print(line + " " + model_state(got["on"][1]), flush=True)
                    ev_off, ev_on = got["off"][0], got["on"][0]
                    if [(e.onset_s, e.onset_uncertain) for e in ev_off] != [
                        (e.onset_s, e.onset_uncertain) for e in ev_on
                    ]:
                        times = sorted({e.detected_at_s for e in ev_off + ev_on} | {STOP_S})
                        for sw, (ev, det) in got.items():
                            print(f"    {sw}: events {_fmt(ev)}")
                            print("      " + "\n      ".join(details(det, times) or ["(nothing noted)"]))
                            print(f"      {model_state(det)}")
    print("\n| generator, rate told | switch | " + " | ".join(OUTCOMES) + " | before (counted / flagged) |")
    print("| --- | --- |" + " --- |" * (len(OUTCOMES) + 1))
    for key, t in tally.items():
        gen, rate, sw = key.split()
        print(
            f"| {gen} {rate} | {sw} | "
            + " | ".join(str(t[o]) for o in OUTCOMES)
            + f" | {t['counted']} / {t['flagged before']} |"
        )
    return tally


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="The lines model off against on, on other generators (docstring).")
    ap.add_argument(
        "--gens", default=",".join(ARMS), help=f"generators, comma-separated, of {list(ARMS)}".replace("%", "%%")
    )
    ap.add_argument("--rates", default=",".join(f"{r:.0f}" for r in RATES), help="told rates, Hz, comma-separated")
    ap.add_argument("--noises", default=",".join(NOISES), help=f"added sound, comma-separated, of {list(NOISES)}")
    ap.add_argument("--switch", default="lines_model", choices=SWITCHES, help="the ClockedParams switch compared")
    a = ap.parse_args()
    g = tuple(a.gens.split(","))
    ns = tuple(a.noises.split(","))
    if any(x not in ARMS for x in g) or any(x not in NOISES for x in ns):
        ap.error("unknown generator or noise")
    main(g, tuple(float(s) for s in a.rates.split(",")), ns, a.switch)
