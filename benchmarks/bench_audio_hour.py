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
``--rate 1150`` to step (and tell) another rate than the tuning's, ``--seed 1`` for another draw of the
same joints (the seed the arm + 1000; 0, the default, is the hour as measured), ``--details`` to print under each
false stop what the confirming detector noted (``ConfirmLog``): the clocked check's verdict, the
onset's doubt, the rejected fires before it, the stepping's lines model's reading (z, weight, each piece's z and
share in phase) and the path (inside a vetoed fire's window). ``docs/audio-log.md`` ("Diagnosis of the hour's false
stops") reads those lines. ``--variants in-step,default`` hears the same samples with
each variant of the clocked check (``VARIANTS``) side by side, one table each. ``--arms 3
--explain 968.82,988.24,2423.50`` reads those fires on the step clock instead (the detector
run to the last, the sound around each rendered with its parts apart; under a minute).
``--crystal --minutes 20 --stops 6`` runs the twelfth generator instead (``tests/support/crystal_sound.py``:
a divided crystal's step clock in bursts, music placed on and beside the joint's lines; its
joints 1-3, no stop, then ``--stops`` recordings per joint of a stop under music on the lines).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # the generators

import math  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import crystal_sound as cs  # noqa: E402
import numpy as np  # noqa: E402
from fan_sound import SR, STEP_DB, Arm, Scene, _steps, render, tuning_scene  # noqa: E402
from hour_sound import KINDS, RMS, Hour, _Band, _Filter, _span_source, _Stepping, spans, stream  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams  # noqa: E402
from stickslip.audio.confirm.checks import Verdicts, WindowChecks  # noqa: E402
from stickslip.audio.confirm.clocked import CLOCKED, ClockedCheck, ClockedParams, OnClock, lines_stop_likeness  # noqa: E402
from stickslip.audio.confirm.detector import ConfirmLog  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuning import tune  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402

FloatArray = np.ndarray


#: per model z read at a fire (the value ``OnClock.still_z`` carries): the model's weight then, each piece's z, and
#: the pieces' share of the locked sub-bands' lines in phase (``--details`` only; filled by :func:`_record_model`)
MODEL_READ: dict[float, tuple[float, list[float], list[float]]] = {}


def _record_model() -> None:
    """Have ``ClockedCheck.model_z`` note, per value it returns, the model's weight and the window's pieces read
    (each piece's z and its locked sub-bands' share in phase). The same arithmetic as the check; nothing changes."""
    inner = ClockedCheck.model_z

    def noted(self: ClockedCheck, after: FloatArray, a: float = math.nan) -> float:
        z = inner(self, after, a)
        m, n = self.model, self.model_n
        if m is not None and n > 0 and math.isfinite(z):
            pieces = [after[k * n : (k + 1) * n] for k in range(max(1, min(self.p.window_pieces, after.size // n)))]
            read = [m.levels(x) for x in pieces]
            on = m.locked >= m.min_locked
            zs = [m.z_of(lv, self.p.model_min_spans, self.p.model_floor_db) for lv, _ in read]
            shares = [float(np.mean(sh[on])) if on.any() else math.nan for _, sh in read]
            MODEL_READ[z] = (m.weight, zs, shares)
        return z

    ClockedCheck.model_z = noted  # type: ignore[method-assign]


def _model_line(on: OnClock) -> str:
    """The model's reading at a fire (``--details``): z, weight, each piece's z and share in phase."""
    if not math.isfinite(on.still_z):
        return "model not read"
    if on.still_z not in MODEL_READ:
        return f"the departed pieces' least z {on.still_z:.2f}"
    w, zs, shares = MODEL_READ[on.still_z]
    step = (
        f"; in step {on.in_step:.2f} of the model's {on.model_share:.2f}, out of phase {on.added_db:+.1f} dB"
        if on.in_step == on.in_step
        else ""
    )
    return (
        f"model z {on.still_z:.2f} at weight {w:.1f}; pieces z {', '.join(f'{v:.2f}' for v in zs)};"
        f" in phase {', '.join(f'{v:.2f}' for v in shares)}{step}"
    )


def details(e: StopEvent, log: ConfirmLog) -> str:
    """What the confirming detector noted about the event ``e``: the clocked check, the onset, the fires before."""
    got = [g for t, g in log.clocked if t == e.detected_at_s]
    clocked = (
        f"a_L {got[0].a:.2f} on {got[0].bands} sub-bands at {got[0].rate_hz:.2f} Hz"
        + (f", against the stepping kept {got[0].kept_s:.2f} s before" if got[0].kept_s == got[0].kept_s else "")
        + (f"; in phase {got[0].locked:.2f}" if got[0].locked == got[0].locked else "")
        + (f"; its lines moved {got[0].moved_db:.2f} dB" if got[0].moved_db == got[0].moved_db else "")
        + f"; {_model_line(got[0])}"
        if got
        else "not judged (reference stop-like, too little heard or rate off)"
    )
    doubt = [why for t, why in log.onset if t == e.detected_at_s]
    before = [r.detected_at_s for r in log.rejected if e.detected_at_s - 30.0 < r.detected_at_s < e.detected_at_s]
    last = f", the last {e.detected_at_s - before[-1]:.2f} s before" if before else ""
    path = [
        f"inside the window of the fire at {t:.2f} s (spread {sp:.3f} s); that fire on the clock: "
        + " / ".join(f"a_L {c.a:.2f}, in phase {c.locked:.2f}, {_model_line(c)}" for u, c in log.clocked if u == t)
        for t, o, sp in log.inside
        if o == e.onset_s
    ]
    path += [f"onset taken back from {a:.2f} s" for t, a, _ in log.retime if t == e.detected_at_s]
    path += [f"rise {r:.3f} s" for t, r in log.rise if t == e.detected_at_s]
    return (
        f"      stop-likeness {e.level_db:.3f}, window {e.confirmed_s or 0.0:.2f} s; onset doubted:"
        f" {doubt[0] if doubt else 'no'}\n      clocked check: {clocked}\n"
        f"      {len(before)} fires rejected in the 30 s before{last}"
        + (f"\n      path: {'; '.join(path)}" if path else "")
    )


#: the clocked check's variants ``--variants`` compares: its lines read on the 0.4 % comb only (two rounds back); read
#: in step, a reference stop-like to the levels giving no verdict and a window read on its first span (the round
#: before); the latest stepping kept no longer than 10 s, 30 s or 120 s before taken for such a reference; a longer
#: window read in four spans, the median kept; both (``spans``, the round before); and with them the lines read in
#: phase with the clock followed from the sound, as a veto only (``veto``); and those lines also affirming a fire the
#: levels hold but not hot, and read from each stop's onset (the default); the default without a stop the lines model
#: could have judged and did not flagged (``unjudged-off``); the default without the model's span gate expecting a
#: jittered clock's loss (``expect-off``); without a fire the levels rejected whose lines departed in every span
#: flagged (``rejected-off``); with every veto of the lines model standing, also one on a single locked sub-band
#: (``bands-off``); without the lines read at the told rate once the clock was heard there (``held-off``); without a
#: rejected window read against the spans heard before the model is ready (``early-off``); with ``onset_short_ref``'s
#: bar ``min_s`` even where the stream's start cut the fire's reference (``short-span-off``)
ROUND_BEFORE = ClockedParams(kept_age_s=0.0, window_pieces=1, locked_frame_s=0.0)
VARIANTS: dict[str, ClockedParams | None] = {
    "before": replace(ROUND_BEFORE, combs=(0.004,)),
    "in-step": ROUND_BEFORE,
    "kept10": replace(ROUND_BEFORE, kept_age_s=10.0),
    "kept30": replace(ROUND_BEFORE, kept_age_s=30.0),
    "kept120": replace(ROUND_BEFORE, kept_age_s=120.0),
    "pieces": replace(ROUND_BEFORE, window_pieces=4),
    "spans": ClockedParams(locked_frame_s=0.0),
    "veto": ClockedParams(min_affirm=math.inf, onset_read_s=0.0),
    "default": ClockedParams(),
    "model": ClockedParams(lines_model=True),
    "per-fire": ClockedParams(lines_model=False),
    "unjudged-off": ClockedParams(model_unjudged=False),
    "expect-off": ClockedParams(model_expect=False),
    "in-step-off": ClockedParams(model_in_step=0.0),
    "edge-off": ClockedParams(model_edge_s=0.0),
    "hold-off": ClockedParams(model_hold_s=0.0),
    "in-step-hold-off": ClockedParams(model_in_step_hold_z=0.0),
    "rejected-off": ClockedParams(model_rejected=False),
    "refired-off": ClockedParams(model_refired=False),
    "onset-off": ClockedParams(model_onset=False),
    "bands-off": ClockedParams(model_min_bands=0),
    "held-off": ClockedParams(told_held_tol=0.0),
    "early-off": ClockedParams(model_rejected_early=False),
    "short-span-off": ClockedParams(onset_short_span=False),
    "off": None,
}


def hour(
    arm: int,
    minutes: float,
    rate: float,
    detail: bool = False,
    variants: tuple[str, ...] = ("default",),
    draw: int = 0,
) -> dict[str, tuple[dict[str, list[float]], list[str]]]:
    """Per variant: per kind [seconds, unflagged, flagged]; and one line per event (two with ``detail``).

    ``draw``: 0 the hour as measured (its seed the arm), N another draw of the same joint (seed the arm + 1000 N,
    clear of every other joint's seeds)."""
    tu = tune(render(tuning_scene(Arm(arm))), SR, 2.0)
    h = Hour(Arm(arm), rate=rate, dur=60.0 * minutes, seed=arm + 1000 * draw)
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
    draw: int = 0,
) -> None:
    print(
        f"{minutes:g} min of stepping at {rate:g} Hz (told, draw {draw}) with speech, music and a radio, no stop: "
        "false stops (unflagged, a wrong count / flagged, refused)"
    )
    print("| joint | clocked check | " + " | ".join(KINDS) + " | all | s |")
    print("| --- " * (len(KINDS) + 4) + "|")
    for arm in arms:
        t = time.perf_counter()
        got = hour(arm, minutes, rate, detail, variants, draw)
        for v, (per, lines) in got.items():
            cells = [f"{int(u)} / {int(f)} in {s / 60:.0f} min" for s, u, f in per.values()]
            u_all, f_all = sum(x[1] for x in per.values()), sum(x[2] for x in per.values())
            print(
                f"| {arm} | {v} | " + " | ".join(cells) + f" | {int(u_all)} / {int(f_all)} |"
                f" {time.perf_counter() - t:.0f} |"
            )
            for line in lines:
                print(line)


# --explain: the fires on the step clock ------------------------------------------------------------------------
# Offline, around each fire: the hour rendered again with its parts apart (the stepping and its step times, the
# room, the added sound; the same samples as ``stream``), the reference and window the clocked check read (the
# detector run to the fire), and per line it judged the stepping's and the added sound's power and the lines'
# phase coherence (``|sum z| / sum |z|`` of 20 ms frames demodulated at the line) with the commanded clock
# (``k * rate * t``: what a traverse knows) and with the steps' own clock (the generator's step times: an oracle,
# the best a clock followed from the sound could do); then ``a_L`` read several ways, against true stops of the
# same joint. ``docs/audio-log.md`` ("Joint 3's three fires under music") reads the tables.

SPAN, GAP, FRAME = 0.48, 0.06, 0.02  # s: the check's reference and window span, its gap; the coherence's frames
NOTES = 110.0 * 2 ** (np.arange(49) / 12)  # the music's notes (``hour_sound._Band``), Hz; 8 harmonics each


class _Timed(_Stepping):
    """The stepping, its step times kept (the same draws in the same order as ``_Stepping``)."""

    def __init__(self, h: Hour, rng: np.random.Generator) -> None:
        super().__init__(h, rng)
        self.times: list[float] = []

    def __call__(self, t0: float, n: int) -> np.ndarray:
        x = np.zeros(n)
        t1 = t0 + n / SR
        while self.next_t < t1:
            self.times.append(self.next_t)
            x[min(n - 1, int(round((self.next_t - t0) * SR)))] += 1.0 + 0.15 * self.rng.standard_normal()
            self.next_t += (1.0 + self.h.jitter * self.rng.standard_normal()) / self.h.rate
        force = self.pulse(x)
        y = sum((m(force) for m in self.modes), np.zeros(n))
        return np.asarray(self.mic(y) * self.scale, dtype=np.float64)


def parts(h: Hour, windows: list[tuple[float, float]]) -> tuple[list[np.ndarray], np.ndarray]:
    """Per window (s, s): its stepping, room and added sound (rows of one float32 array), as ``stream`` renders
    them; and every step time up to the last window, s."""
    rng = np.random.default_rng(h.seed)
    step = _Timed(h, np.random.default_rng(h.seed + 1))
    probe = _Stepping(h, np.random.default_rng(h.seed + 2))
    ref = probe(0.0, SR)
    step.scale = 10 ** (STEP_DB / 20) / float(np.sqrt(np.mean(ref[SR // 4 :] ** 2)))
    step_rms = 10 ** (STEP_DB / 20)
    room = _Filter(np.array([0.049922, -0.095993, 0.050612, -0.004408]), np.array([1, -2.494956, 2.017265, -0.522189]))
    room_gain = step_rms * 10 ** (-h.snr_db / 20) / 0.0857
    sched, k, src, gain = spans(h), -1, None, 0.0
    cut = [(int(round(a * SR)), int(round(b * SR))) for a, b in windows]
    out = [np.zeros((3, b - a), dtype=np.float32) for a, b in cut]
    total, nb = max(b for _, b in cut), int(round(h.block_s * SR))
    for done in range(0, total, nb):
        n = min(nb, total - done)
        blk = np.zeros((3, n))
        blk[0], blk[1] = step(done / SR, n), room_gain * room(rng.standard_normal(n))
        pos = 0
        while pos < n:
            while k + 1 < len(sched) and sched[k + 1][0] <= (done + pos) / SR:
                k += 1
                src = _span_source(sched[k][2], np.random.default_rng(h.seed + 100 + k))
                gain = step_rms * 10 ** (sched[k][3] / 20) / RMS.get(sched[k][2], 1.0)
            end = max(pos + 1, min(n, int(round(sched[k][1] * SR)) - done) if k >= 0 else n)
            if src is not None:
                blk[2, pos:end] = gain * src(end - pos)  # type: ignore[operator]
            pos = end
        for (a, b), o in zip(cut, out, strict=True):
            lo, hi = max(a, done), min(b, done + n)
            if lo < hi:
                o[:, lo - a : hi - a] = blk[:, lo - done : hi - done]
    return out, np.asarray(step.times)


def judged_lines(tu: Tuning, rate: float) -> list[tuple[int, int]]:
    """(sub-band, harmonic) of every line the clocked check judges: sub-bands the stop moves, on the lines."""
    assert tu.edges_hz is not None and tu.signature_db is not None and tu.continuum_signature_db is not None
    out = []
    for i, (d, c) in enumerate(zip(tu.signature_db, tu.continuum_signature_db, strict=True)):
        if abs(d) >= CLOCKED.min_signature_db and math.copysign(1.0, d) * c <= abs(d) + CLOCKED.max_continuum_excess_db:
            lo, hi = tu.edges_hz[i], tu.edges_hz[i + 1]
            out += [(i, k) for k in range(int(math.ceil(lo / rate)), int(hi / rate) + 1) if lo <= k * rate < hi]
    return out


def comb_power(x: np.ndarray, f: float) -> tuple[float, float]:
    """Power on the line at ``f`` Hz (the check's comb: 3 bins or 0.4 %, the wider) and beside it (the ring out to
    four times that), per bin, of a Hann-windowed periodogram."""
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    fr = np.fft.rfftfreq(x.size, 1 / SR)
    w = max(3 * SR / x.size, 0.004 * f)
    on, ring = np.abs(fr - f) <= w, (np.abs(fr - f) > w) & (np.abs(fr - f) <= 4 * w)
    return float(np.mean(spec[on])), float(np.mean(spec[ring]))


def coherence(x: np.ndarray, t0: float, k: int, phase: np.ndarray | None, rate: float) -> float:
    """``|sum z| / sum |z|`` over 20 ms frames of ``x`` (starting at ``t0`` s) demodulated at the ``k``-th line of
    the clock: ``phase`` (the steps' phase, cycles, per sample) or the commanded ``rate * t`` (None)."""
    t = t0 + np.arange(x.size) / SR
    ph = rate * t if phase is None else phase
    m = int(FRAME * SR)
    n = x.size - x.size % m
    z = (x[:n] * np.exp(-2j * np.pi * k * ph[:n])).reshape(-1, m).sum(axis=1)
    return float(np.abs(z.sum()) / (np.abs(z).sum() + 1e-300))


def step_phase(times: np.ndarray, t0: float, n: int) -> np.ndarray:
    """The steps' phase (cycles) at ``n`` samples from ``t0`` s: the step count, linear between steps."""
    t = t0 + np.arange(n) / SR
    return np.interp(t, times, np.arange(times.size, dtype=np.float64))


def follow_phase(x: np.ndarray, t0: float, rate: float, harmonics: int = 12) -> np.ndarray:
    """The steps' phase (cycles, per sample of ``x`` from ``t0`` s) followed from the sound: per 20 ms frame the
    lines 1..``harmonics`` at the commanded ``rate``, the clock's offset the one within 0.04 cycles of the last frame's
    that best matches a running template of those lines (its first frame, then 5 % of each new frame, aligned)."""
    m = int(FRAME * SR)
    n = x.size - x.size % m
    tt = (t0 + np.arange(n) / SR).reshape(-1, m)
    ks = np.arange(1, harmonics + 1)
    z = np.stack([(x[:n].reshape(-1, m) * np.exp(-2j * np.pi * k * rate * tt)).sum(axis=1) for k in ks], axis=1)
    grid, tmpl, th = np.linspace(-0.04, 0.04, 101), z[0].copy(), 0.0
    off = np.zeros(z.shape[0])
    for f in range(z.shape[0]):
        cand = th + grid
        score = np.real(np.exp(-2j * np.pi * np.outer(cand, ks)) @ (z[f] * np.conj(tmpl)))
        th = float(cand[int(np.argmax(score))])
        off[f] = th
        tmpl = 0.95 * tmpl + 0.05 * z[f] * np.exp(-2j * np.pi * ks * th)
    ts = t0 + np.arange(x.size) / SR
    return np.asarray(rate * ts + np.interp(ts, t0 + (np.arange(off.size) + 0.5) * m / SR, off), dtype=np.float64)


def _a(tu: Tuning, ref: np.ndarray, win: np.ndarray, rate: float, pieces: int, combs: tuple[float, ...]) -> float:
    """The check's ``a_L`` (``lines_stop_likeness``), the median over up to ``pieces`` spans of ``win``."""
    assert tu.edges_hz is not None and tu.signature_db is not None and tu.continuum_signature_db is not None
    p = replace(CLOCKED, combs=combs)
    n = ref.size
    got = [
        lines_stop_likeness(ref, win[j * n : (j + 1) * n], SR, rate, tu.edges_hz, tu.signature_db,
                            tu.continuum_signature_db, p)[0]
        for j in range(max(1, min(pieces, win.size // n)))
    ]  # fmt: skip
    finite = [g for g in got if math.isfinite(g)]
    return float(np.median(finite)) if finite else math.nan


def _coherent_a(
    tu: Tuning, lines: list[tuple[int, int]], ref: np.ndarray, win: np.ndarray, ph_ref: np.ndarray, ph_win: np.ndarray
) -> float:
    """``a_L`` from the lines' power locked to the steps' clock (``|mean z|^2`` of 20 ms frames demodulated at
    ``k`` times the steps' phase), per sub-band judged, the median over the window's spans."""
    assert tu.signature_db is not None
    m = int(FRAME * SR)
    n = ref.size - ref.size % m

    def locked(x: np.ndarray, ph: np.ndarray, ks: list[int]) -> float:
        return sum(float(np.abs((x[:n] * np.exp(-2j * np.pi * k * ph[:n])).reshape(-1, m).sum(axis=1).mean()) ** 2)
                   for k in ks)  # fmt: skip

    out = []
    for j in range(max(1, min(4, win.size // ref.size))):
        s = slice(j * ref.size, (j + 1) * ref.size)
        num = den = 0.0
        for b in sorted({b for b, _ in lines}):
            ks = [k for bb, k in lines if bb == b]
            p0, p1 = locked(ref, ph_ref, ks), locked(win[s], ph_win[s], ks)
            top = max(p0, p1) * CLOCKED.floor_share
            d, delta = 10 * math.log10(max(p1, top) / max(p0, top)), float(tu.signature_db[b])
            num, den = num + delta * d, den + delta**2
        out.append(num / den)
    return float(np.median(out))


@dataclass(frozen=True)
class Read:
    """One judgement on the lines: the reference and the window as the check read them (s on the parts' clock)."""

    name: str
    ref_lo: float
    win_lo: float
    win_s: float
    rate: float  # the step rate the lines were read at, Hz
    a: float = math.nan  # the confirming detector's a_L (NaN: no verdict, or not run)


def heard_fires(arm: int, rate: float, until_s: float) -> list[Read]:
    """The hour heard by the confirming detector up to ``until_s``: per fire judged on the lines, the reference
    (its chain's, or the stepping kept) and the window it read, the rate and ``a_L``. Offline: the check's
    ``hear_before`` and ``_on_clock`` are wrapped for the run (their positions are not in ``ConfirmLog``)."""
    tu = tune(render(tuning_scene(Arm(arm))), SR, 2.0)
    h = Hour(Arm(arm), rate=rate, dur=3600.0, seed=arm)
    det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams())
    det.reset(0.0, step_rate_hz=rate)
    out: list[Read] = []
    hear, judge = ClockedCheck.hear_before, WindowChecks._on_clock

    def heard(self: ClockedCheck, ref: FloatArray, margins: FloatArray, end: int | None = None) -> None:
        hear(self, ref, margins, end)
        kept = math.isfinite(self.ref_age_s)
        self.ref_end = None if end is None else end - (self.ref_age_s * self.sample_rate if kept else 0.0)  # type: ignore[attr-defined]

    def judged(self: WindowChecks, ev: StopEvent, fire: int, frames: int, log: Verdicts) -> bool:
        n, ok = len(log.clocked), judge(self, ev, fire, frames, log)
        c = self.clocked
        if len(log.clocked) > n and c is not None and c.ref is not None and getattr(c, "ref_end", None) is not None:
            got = log.clocked[-1][1]
            win = min(c.p.window_pieces * self.span, frames * self._H) / SR
            lo = (c.ref_end - c.ref.size) / SR  # type: ignore[attr-defined]
            out.append(Read(f"{ev.onset_s:.2f} s", lo, (fire * self._H + self._F) / SR, win, got.rate_hz, got.a))
        return ok

    ClockedCheck.hear_before, WindowChecks._on_clock = heard, judged  # type: ignore[method-assign]
    try:
        for k, block in enumerate(stream(h)):
            det.feed(block)
            if k * h.block_s > until_s:
                break
    finally:
        ClockedCheck.hear_before, WindowChecks._on_clock = hear, judge  # type: ignore[method-assign]
    return out


@dataclass(frozen=True)
class Case:
    """A judgement and the sound around it: parts as rows (the stepping, the room, the added), from ``t0`` s."""

    read: Read
    w: np.ndarray
    t0: float
    phase: np.ndarray  # the steps' phase, cycles, per sample of ``w``

    def cut(self, row: int | None, lo: float, dur: float) -> np.ndarray:
        """``dur`` s from ``lo`` s of one part (None: the sound heard, all three)."""
        i = int(round((lo - self.t0) * SR))
        x = self.w.sum(axis=0) if row is None else self.w[row]
        return np.asarray(x[i : i + int(round(dur * SR))], dtype=np.float64)

    def ph(self, lo: float, dur: float) -> np.ndarray:
        i = int(round((lo - self.t0) * SR))
        return self.phase[i : i + int(round(dur * SR))]


def _db(x: float, ref: float) -> str:
    return "none" if x <= ref * 1e-12 else f"{10 * math.log10(x / ref):+.1f}"


def line_rows(c: Case, lines: list[tuple[int, int]], commanded: float) -> list[str]:
    """Per line: the stepping's power on it, window against reference; the added sound's on it in the reference
    and the window and beside it in the window (dB re the stepping's line in the reference); the coherence of the
    sound heard with the commanded clock and with the steps' clock over 0.5 s and 2 s; the added sound's alone."""
    r = c.read
    rows = []
    for b, k in lines:
        f = k * r.rate
        s0, _ = comb_power(c.cut(0, r.ref_lo, SPAN), f)
        s1, _ = comb_power(c.cut(0, r.win_lo, SPAN), f)
        m0, _ = comb_power(c.cut(2, r.ref_lo, SPAN), f)
        m1, beside = comb_power(c.cut(2, r.win_lo, SPAN), f)
        d2 = min(4 * SPAN, r.win_s)
        coh = [coherence(c.cut(None, r.win_lo, d), r.win_lo, k, None, commanded) for d in (SPAN, d2)]
        coh += [coherence(c.cut(None, r.win_lo, d), r.win_lo, k, c.ph(r.win_lo, d), commanded) for d in (SPAN, d2)]
        alone = coherence(c.cut(2, r.win_lo, d2), r.win_lo, k, c.ph(r.win_lo, d2), commanded)
        near = [f"{kk}x{g:.0f}" for g in NOTES for kk in range(1, 9) if abs(kk * g - f) <= 0.016 * f]
        rows.append(
            f"| {r.name} | {k} ({f:.0f} Hz, {b + 1}) | {_db(s1, s0)} | {_db(m0, s0)} / {_db(m1, s0)} /"
            f" {_db(beside, s0)} | {coh[0]:.2f} / {coh[1]:.2f} | {coh[2]:.2f} / {coh[3]:.2f} |"
            f" {'--' if m1 <= s0 * 1e-12 else f'{alone:.2f}'} | {', '.join(near)} |"
        )
    return rows


def a_row(c: Case, tu: Tuning, lines: list[tuple[int, int]], quiet: float | None, commanded: float) -> str:
    """``a_L``: the detector's; read again here on its reference and window (0.5 s; the 2 s median); on the 3-bin
    comb only; against the quietest 0.48 s of the minute before; without the added sound; from the power locked
    to the steps' clock; and from the power locked to the clock followed from the sound (``follow_phase``)."""
    r = c.read
    ref, win = c.cut(None, r.ref_lo, SPAN), c.cut(None, r.win_lo, r.win_s)
    heard = Case(r, c.w, c.t0, follow_phase(c.w.sum(axis=0).astype(np.float64), c.t0, commanded))
    followed = (heard.ph(r.ref_lo, SPAN), heard.ph(r.win_lo, r.win_s))
    dry = [
        c.cut(0, r.ref_lo, SPAN) + c.cut(1, r.ref_lo, SPAN),
        c.cut(0, r.win_lo, r.win_s) + c.cut(1, r.win_lo, r.win_s),
    ]
    got = [
        r.a,
        _a(tu, ref, win, r.rate, 1, CLOCKED.combs),
        _a(tu, ref, win, r.rate, 4, CLOCKED.combs),
        _a(tu, ref, win, r.rate, 4, (0.0,)),
        math.nan if quiet is None else _a(tu, c.cut(None, quiet, SPAN), win, r.rate, 4, CLOCKED.combs),
        _a(tu, dry[0], dry[1], r.rate, 4, CLOCKED.combs),
        _coherent_a(tu, lines, ref, win, c.ph(r.ref_lo, SPAN), c.ph(r.win_lo, r.win_s)),
        _coherent_a(tu, lines, ref, win, *followed),
    ]
    return f"| {r.name} | " + " | ".join("--" if not math.isfinite(x) else f"{x:.2f}" for x in got) + " |"


def minute_before(c: Case, tu: Tuning, at: float, lines: list[tuple[int, int]], commanded: float) -> tuple[str, float]:
    """``a_L`` over the minute before ``at`` s, each 0.48 s span against the one before it: the check's, and from the
    power locked to the clock followed from the sound (each: the largest, how many at ``min_a`` or more); and the
    start of the span with the least added sound, s."""
    r, sp = c.read, SPAN
    lo = max(c.t0, at - 60.0)
    n = int((at - 1.0 - lo) / sp)
    pairs = [(lo + (j - 1) * sp, lo + j * sp) for j in range(1, n)]
    heard = Case(r, c.w, c.t0, follow_phase(c.w.sum(axis=0).astype(np.float64), c.t0, commanded))
    got = [_a(tu, c.cut(None, a0, sp), c.cut(None, a1, sp), r.rate, 1, CLOCKED.combs) for a0, a1 in pairs]
    locked = [
        _coherent_a(tu, lines, c.cut(None, a0, sp), c.cut(None, a1, sp), heard.ph(a0, sp), heard.ph(a1, sp))
        for a0, a1 in pairs
    ]
    quiet = int(np.argmin([np.sum(c.cut(2, lo + j * sp, sp) ** 2) for j in range(n)]))
    out = []
    for name, vals in (("the check", got), ("locked to the clock followed", locked)):
        fin = np.asarray([g for g in vals if math.isfinite(g)])
        top = f"the largest {fin.max():.2f}, {int(np.sum(fin >= CLOCKED.min_a))} at {CLOCKED.min_a} or more"
        out.append(f"{name}: {fin.size} of {len(vals)} judged" + (f", {top}" if fin.size else ""))
    return "; ".join(out), lo + quiet * sp


def stop_cases(arm: int, rate: float) -> list[Case]:
    """True stops of the joint: its tuning recording, two quiet stops, the same two under the hour's music at
    +2.5 dB re the stepping (parts: the recording, nothing, the music), read as the check would at the stop."""
    scenes: list[tuple[str, Scene, float | None]] = [("tuning's stop", tuning_scene(Arm(arm)), None)]
    for seed in (2, 3):
        sc = Scene(arm=Arm(arm), rate=rate, stop_at=2.5, dur=4.6, seed=seed)
        scenes += [(f"stop, draw {seed}", sc, None), (f"stop, draw {seed}, music", sc, 2.5)]
    out = []
    for name, sc, db in scenes:
        x = render(sc).astype(np.float64)
        music = np.zeros_like(x)
        if db is not None:
            gain = 10 ** ((STEP_DB + db) / 20) / RMS["music"]
            music = gain * _Band(np.random.default_rng(sc.seed + 50))(x.size)
        times = _steps(sc, x.size, np.random.default_rng(sc.seed)) / SR
        at = float(sc.stop_at or 0.0)
        read = Read(name, at - GAP - SPAN, at, min(4 * SPAN, sc.dur - at - 0.01), rate)
        w = np.stack([x, np.zeros_like(x), music]).astype(np.float32)
        out.append(Case(read, w, 0.0, step_phase(times, 0.0, x.size)))
    return out


HEAD_LINES = (
    "| fire | line k (Hz, sub-band) | stepping on it, window re reference, dB | added on it in the reference / in the"
    " window / beside it, dB re the stepping's line | coherence, commanded clock, 0.5 / 2 s | steps' clock,"
    " 0.5 / 2 s | the added alone, steps' clock, 2 s | the scale's partials within 1.6 % (k x Hz) |\n"
    + "| --- " * 8
    + "|"
)
HEAD_A = (
    "| fire | a_L, detector | read again, 0.5 s | 2 s (median) | 3-bin comb only | against the quietest 0.48 s"
    " of the minute before | without the added sound | power locked to the steps' clock | to the clock followed"
    " from the sound |\n" + "| --- " * 9 + "|"
)


def explain(arm: int, fires: list[float], rate: float) -> None:
    """Print, for the fires (onsets, s) of joint ``arm``'s hour and for the joint's true stops, the lines judged
    and ``a_L`` read several ways (``--explain``)."""
    tu = tune(render(tuning_scene(Arm(arm))), SR, 2.0)
    lines = judged_lines(tu, rate)
    print(f"joint {arm}: lines judged (sub-band, harmonic) {lines}; the signature {tu.signature_db} dB")
    reads = heard_fires(arm, rate, max(fires) + 3.0)
    mine = [next((r for r in reads if abs(r.win_lo - t) < 0.2), None) for t in fires]
    for t, r in zip(fires, mine, strict=True):
        if r is None:
            print(f"{t:.2f} s: no fire judged on the lines there (the window's start within 0.2 s)")
    got = [r for r in mine if r is not None]
    if not got:
        return
    h = Hour(Arm(arm), rate=rate, dur=3600.0, seed=arm)
    w, times = parts(h, [(max(0.0, min(r.ref_lo, r.win_lo - 60.0) - 1.0), r.win_lo + r.win_s + 0.1) for r in got])
    cases: list[Case] = []
    quiet: list[float | None] = []
    for r, x in zip(got, w, strict=True):
        t0 = max(0.0, min(r.ref_lo, r.win_lo - 60.0) - 1.0)
        c = Case(r, x, t0, step_phase(times, t0, x.shape[1]))
        s = next(x for x in spans(h) if x[0] <= r.win_lo < x[1])
        summary, q = minute_before(c, tu, r.win_lo, lines, rate)
        print(f"{r.name}: {s[2]} at {s[3]:+.1f} dB ({s[0]:.1f}-{s[1]:.1f} s); the reference {r.ref_lo:.2f} s,")
        print(f"  the window {r.win_lo:.2f} s + {r.win_s:.2f} s at {r.rate:.2f} Hz;")
        print(f"  the minute before, {summary}")
        cases.append(c)
        quiet.append(q)
    stops = stop_cases(arm, rate)
    print(HEAD_LINES)
    for c in cases + stops:
        print("\n".join(line_rows(c, lines, rate)))
    print(HEAD_A)
    for c, qs in zip(cases + stops, [*quiet, *[None] * len(stops)], strict=True):
        print(a_row(c, tu, lines, qs, rate))


# --crystal: the twelfth generator (``tests/support/crystal_sound.py``): a divided crystal's step clock with a slow
# drift, bursts whose phase restarts, a per-step amplitude spread, and music placed on and beside the joint's lines.
# Written before the check was changed for it; measured, never tuned to.


def crystal(
    joint: int, minutes: float, detail: bool, variants: tuple[str, ...], stops: int
) -> dict[str, tuple[list[str], list[str], tuple[int, int]]]:
    """Per variant: the false stops of ``minutes`` of joint ``joint`` stepping with no stop, and the first events of
    ``stops`` recordings of a stop under music on the lines (right: within 50 ms unflagged)."""
    tu = tune(cs.render(cs.tuning_session(cs.Joint(joint))), SR, 2.0)
    s = cs.Session(cs.Joint(joint), dur=60.0 * minutes, seed=joint)
    dets = {v: ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=VARIANTS[v])) for v in variants}
    heard: dict[str, list[StopEvent]] = {v: [] for v in variants}
    for d in dets.values():
        d.reset(0.0, step_rate_hz=s.clock.rate)
    for block in cs.stream(s):
        for v, d in dets.items():
            heard[v] += d.feed(block)
    sched = cs.spans(s)
    out: dict[str, tuple[list[str], list[str], tuple[int, int]]] = {}
    for v, d in dets.items():
        lines, evs = [], heard[v] + d.finish()
        for e in evs:
            kind = next(k for a, b, k in sched if a <= e.onset_s < b)
            lines.append(f"    {e.onset_s:8.2f} s  {'flagged' if e.onset_uncertain else 'COUNTED'}  {kind}")
            if detail:
                lines.append(details(e, d.log))
        out[v] = (lines, [], (sum(not e.onset_uncertain for e in evs), sum(e.onset_uncertain for e in evs)))
    rng = np.random.default_rng(joint + 900)
    for k in range(stops):
        at = float(rng.uniform(3.0, 5.0))
        sc = cs.Session(cs.Joint(joint), dur=at + 2.5, stop_at=at, seed=1000 + 10 * joint + k,
                        kinds=("music on the lines",), span_s=(20.0, 30.0))  # fmt: skip
        x = cs.render(sc)
        for v in variants:
            det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=VARIANTS[v]))
            det.reset(0.0, step_rate_hz=sc.clock.rate)
            ev = det.feed(x) + det.finish()
            out[v][1].append(_stop_verdict(ev, at))
    return out


def _stop_verdict(events: list[StopEvent], at: float) -> str:
    """The first event against the stop at ``at`` s: right (within 50 ms), flagged, early, late or missed."""
    if not events:
        return "missed"
    e = events[0]
    err = e.onset_s - at
    if e.onset_uncertain:
        return "flagged"
    return "right" if abs(err) <= 0.05 else ("early" if err < 0 else "late")


def crystal_main(joints: tuple[int, ...], minutes: float, detail: bool, variants: tuple[str, ...], stops: int) -> None:
    print(
        f"the twelfth generator: {minutes:g} min of stepping at 1000 Hz (told) on a divided crystal in bursts, music "
        f"on and beside the lines, no stop; and {stops} stops under music on the lines"
    )
    print(
        "| joint | clocked check | false stops counted / flagged | stops: right / flagged / early / late / missed | s |"
    )
    print("| --- " * 5 + "|")
    for j in joints:
        t = time.perf_counter()
        for v, (lines, verdicts, (u, f)) in crystal(j, minutes, detail, variants, stops).items():
            tally = " / ".join(str(verdicts.count(w)) for w in ("right", "flagged", "early", "late", "missed"))
            print(f"| {j} | {v} | {u} / {f} | {tally} | {time.perf_counter() - t:.0f} |")
            for line in lines:
                print(line)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="An hour of stepping under speech, music and a radio (docstring).")
    ap.add_argument("--arms", default="1,2,3", help="arms of the tenth generator, comma-separated")
    ap.add_argument("--minutes", type=float, default=60.0, help="minutes of stepping per joint")
    ap.add_argument("--rate", type=float, default=1000.0, help="the step rate, Hz (told to the detector)")
    ap.add_argument("--details", action="store_true", help="what the detector noted about each false stop")
    ap.add_argument("--seed", type=int, default=0, help="the draw: 0 as measured, N another (seed arm + 1000 N)")
    ap.add_argument("--variants", default="default", help=f"the clocked check's variants: {', '.join(VARIANTS)}")
    ap.add_argument("--crystal", action="store_true", help="the twelfth generator instead (a crystal's clock)")
    ap.add_argument("--stops", type=int, default=6, help="with --crystal: stops under music on the lines, per joint")
    ap.add_argument("--explain", default="", help="fires' onsets, s, comma-separated: read them on the step clock")
    a = ap.parse_args()
    if a.explain:
        try:
            fires = [float(x) for x in a.explain.split(",")]
        except ValueError:
            ap.error(f"--explain: onsets in s, comma-separated (got {a.explain})")
        if not all(0.0 < t < 3600.0 for t in fires):
            ap.error(f"--explain: onsets within the hour, 0-3600 s (got {a.explain})")
        for arm in (int(x) for x in a.arms.split(",")):
            explain(arm, fires, a.rate)
        sys.exit(0)
    vs = tuple(a.variants.split(","))
    if not set(vs) <= set(VARIANTS):
        ap.error(f"--variants: one of {', '.join(VARIANTS)}, comma-separated (got {a.variants})")
    if a.crystal:
        crystal_main(tuple(int(x) for x in a.arms.split(",")), a.minutes, a.details, vs, a.stops)
        sys.exit(0)
    if a.seed < 0:
        ap.error(f"--seed: a draw, 0 or more (got {a.seed})")
    if a.details:
        _record_model()
    main(tuple(int(x) for x in a.arms.split(",")), a.minutes, a.rate, a.details, vs, a.seed)
