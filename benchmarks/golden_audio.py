"""The audio detector's golden comparison: the same inputs give the same events, before and after a change.

A refactoring of :mod:`stickslip.audio` that means to change nothing is checked here, not by
eye: ``record`` runs the tuner and every detector over a fixed set of recordings from the
generators in ``tests/`` (the battery's conditions, the fourth to eighth generators, the
simulator, a vibration stream, sessions with several stops and with pauses, the version-1
band detector) and writes what comes out - every tuning file, every event with all its
fields, the confirming detector's logs and a hash of the per-frame evidence - to a JSON
file; ``compare`` runs the same again and reports every difference (floats: equal, or
within 1e-12 relative, or different).

Run ``python benchmarks/golden_audio.py record /tmp/golden.json`` before a change and
``python benchmarks/golden_audio.py compare /tmp/golden.json`` after it (a few minutes on
one core; ``--quick`` for a subset). Not a test: it is for refactorings, and takes minutes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, is_dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the batteries (test_audio_*.py)
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "support"))  # the generators

import alien_sound as al  # noqa: E402
import arrival_sound as ar  # noqa: E402
import battery_sound as bs  # noqa: E402
import beam_sound as bm  # noqa: E402
import drive_sound as dv  # noqa: E402
import line_sound as ln  # noqa: E402
import modal_sound as ms  # noqa: E402
import shaped_sound as sh  # noqa: E402

# --- the detector's API (the one place that names it) ---------------------------------------------------------------
from stickslip.audio.confirm import ConfirmedStopDetector, confirming  # noqa: E402
from stickslip.audio.detector import detect, detector_for  # noqa: E402
from stickslip.audio.sources.vibration import read_vibration  # noqa: E402
from stickslip.audio.tuning import TuningError, tune, tune_band  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402
from stickslip.sim.sound import render_traverse_recording  # noqa: E402

SR = 48_000


def fast_detector(tu: Tuning) -> Any:
    """The detector that fires (no confirmation), with its per-frame evidence collected."""
    det = detector_for(tu)
    det.evidence, det.hot_evidence = [], []
    return det


def template_logs(det: Any) -> dict[str, Any]:
    st = getattr(det, "state", None)
    if st is None:
        return {}
    return {"stale": st.stale.log, "rate": st.fits.rate_log, "relearned": st.relearned}


def confirmed_logs(det: Any) -> dict[str, Any]:
    log = det.log
    return {
        "rejected": log.rejected,
        "onset": log.onset,
        "rise": log.rise,
        "retime": log.retime,
        "stopped": log.stopped,
        "step_clock": log.step_clock,
        "late_swallowed": log.late_swallowed,
        "late": det.late.log if det.late is not None else None,
        "inner": template_logs(det.inner),
    }


# --- plain data ------------------------------------------------------------------------------------------------------
def plain(v: Any) -> Any:
    """JSON-ready: dataclasses and named tuples as dicts, arrays as lists, floats kept exactly (repr)."""
    if is_dataclass(v) and not isinstance(v, type):
        return {k: plain(x) for k, x in asdict(v).items()}
    if isinstance(v, tuple) and hasattr(v, "_asdict"):
        return {k: plain(x) for k, x in v._asdict().items()}
    if isinstance(v, dict):
        return {str(k): plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return plain(v.tolist())
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    return v


def digest(values: list[Any], dtype: Any) -> str:
    a = np.asarray(values, dtype=dtype)
    return f"{a.size}:{hashlib.sha256(a.tobytes()).hexdigest()[:16]}"


# --- what one recording gives ----------------------------------------------------------------------------------------
def hear(tu: Tuning, y: np.ndarray, block: int = 1024, late: bool = True, step_clock: bool = False) -> dict[str, Any]:
    """The fast path's fires and evidence, and the confirmed events (with the late path) and logs."""
    y = np.asarray(y)
    det = fast_detector(tu)
    fires = [e for i in range(0, y.size, block) for e in det.feed(y[i : i + block])]
    out: dict[str, Any] = {
        "fires": plain(fires),
        "evidence": digest(det.evidence, np.float64),
        "hot": digest(det.hot_evidence, np.bool_),
        "fast_logs": plain(template_logs(det)),
    }
    c = confirming(fast_detector(tu), 0.5, step_clock=step_clock, late=late)
    assert isinstance(c, ConfirmedStopDetector)
    events = [e for i in range(0, y.size, block) for e in c.feed(y[i : i + block])] + c.finish()
    out["confirmed"] = plain(events)
    out["logs"] = plain(confirmed_logs(c))
    if late:
        out["detect_plain"] = plain(detect(y, tu, block=block, confirm_s=0.5))
    return out


def tuned(x: np.ndarray, sr: int, stop: float, **kw: Any) -> tuple[Tuning | None, dict[str, Any]]:
    try:
        tu = tune(np.asarray(x), sr, stop, **kw)
    except TuningError as e:
        return None, {"refused": str(e)}
    return tu, plain(tu.to_dict())


# --- the cases -------------------------------------------------------------------------------------------------------
Case = tuple[str, Callable[[], dict[str, Any]]]


def battery_cases(quick: bool) -> Iterator[Case]:
    import test_audio_battery as tb

    conds = tb.CONDITIONS[::5] if quick else tb.CONDITIONS
    for c in conds:
        if tb._needs_espeak(c) and bs.espeak_speech(SR) is None:
            continue

        def run(c: Any = c) -> dict[str, Any]:
            x, sr = bs.render(c.train)
            label = c.label_s if c.label_s is not None else (c.train.stop_at or 1.5)
            tu, rec = tuned(x, sr, label, seed=0)
            out: dict[str, Any] = {"tuning": rec}
            if tu is None:
                return out
            y, sr_t = bs.render(c.test)
            if y.ndim == 2:
                y = y.mean(axis=1)
            if c.lead_s:
                room = 10 ** (-65 / 20) * np.random.default_rng(c.test.seed).standard_normal(int(c.lead_s * sr_t))
                y = np.concatenate((room.astype(np.float32), y))
            try:
                tu_t = tu.for_sample_rate(sr_t)
            except ValueError as e:
                out["listen"] = str(e)
                return out
            out["heard"] = hear(tu_t, y)
            out["step_clock"] = plain(hear(tu_t, y, late=False, step_clock=True)["confirmed"])
            out["outcome"] = repr(tb.run(c))
            return out

        yield f"battery: {c.name}", run


@cache
def modal_tuning(js: int, kind: str) -> tuple[Tuning | None, str]:
    tu, rec = tuned(ms.render(ms.Scene(js, kind, stop_at=3.0, dur=4.5, seed=10)).astype(np.float32), SR, 3.0)
    return tu, json.dumps(rec)


def modal_cases(quick: bool) -> Iterator[Case]:
    rooms: list[dict[str, Any]] = [
        {}, {"instrument": True}, {"voice_db": 0.0}, {"knocks": True}, {"door": True}, {"fan": True},
        {"snr_db": 10.0}, {"rate": 1150.0},
    ]  # fmt: skip
    arms = (2, 5) if quick else (1, 2, 3, 4, 5, 6)
    for js in arms:
        for kind in ms.KINDS:

            def run(js: int = js, kind: str = kind) -> dict[str, Any]:
                tu, rec = modal_tuning(js, kind)
                out: dict[str, Any] = {"tuning": json.loads(rec)}
                if tu is None:
                    return out
                for i, kw in enumerate(rooms[:3] if quick else rooms):
                    seed = 90 + i
                    stop = 2.0 + 0.25 * (seed % 7)
                    x = ms.render(ms.Scene(js, kind, stop_at=stop, seed=seed, **kw)).astype(np.float32)
                    out[f"room {i}"] = hear(tu, x)
                return out

            yield f"modal: arm {js} {kind}", run


@cache
def arrival_tuning(seed: int, kind: str) -> tuple[Tuning | None, str]:
    tu, rec = tuned(ar.render(ar.tuning_scene(ar.Arm(seed, kind))), SR, 2.0)
    return tu, json.dumps(rec)


def arrival_cases(quick: bool) -> Iterator[Case]:
    for seed0, n, clear in ((11, 8 if quick else 40, False), (100, 4 if quick else 30, True)):
        rng = np.random.default_rng(seed0)
        for k in range(n):
            s = ar.draw(rng)
            arm = ar.Arm(int(rng.integers(1, 7)), s.arm.stop_kind)
            before = bool(rng.integers(2))
            start = (-0.05 - s.burst_s if before else 0.05) if clear else s.burst_from
            s = ar.Scene(**{**s.__dict__, "arm": arm, "burst_from": start})

            def run(s: ar.Scene = s) -> dict[str, Any]:
                tu, rec = arrival_tuning(s.arm.seed, s.arm.stop_kind)
                out: dict[str, Any] = {"tuning": json.loads(rec)}
                if tu is not None:
                    out["heard"] = hear(tu, ar.render(s))
                return out

            yield f"arrival: {seed0} #{k}", run


def other_generator_cases(quick: bool) -> Iterator[Case]:
    def drive(arm: int, kind: str, drive_db: float, rate: float, jitter_us: float, seed: int) -> dict[str, Any]:
        tu, rec = tuned(dv.render(dv.tuning_scene(dv.Arm(arm, kind), drive_db)), SR, 2.0)
        out: dict[str, Any] = {"tuning": rec}
        if tu is not None:
            kw = {"drive_db": drive_db, "jitter_us": jitter_us, "seed": seed}
            scene = dv.Scene(arm=dv.Arm(arm, kind), rate=rate, stop_at=1.6, dur=2.6, **kw)
            out["heard"] = hear(tu, dv.render(scene))
        return out

    for arm, kind, db in ((1, "blocked", 0.0), (2, "muted", -6.0), (3, "spectral", 6.0))[: 1 if quick else 3]:
        yield f"drive: arm {arm} {kind}", lambda a=arm, k=kind, d=db: drive(a, k, d, 1020.0, 10.0, 61 + a)

    def beam(b: int, seed: int) -> dict[str, Any]:
        tu, rec = tuned(bm.render(bm.tuning_scene(bm.Beam(b))), SR, 2.0)
        out: dict[str, Any] = {"tuning": rec}
        if tu is not None:
            out["heard"] = hear(tu, bm.render(bm.Scene(beam=bm.Beam(b), stop_at=1.9, seed=seed)))
        return out

    for b in (1, 3) if quick else (1, 2, 3, 5, 8):
        yield f"beam: {b}", lambda b=b: beam(b, 40 + b)

    def line(arm: int, seed: int) -> dict[str, Any]:
        tu, rec = tuned(ln.render(ln.Scene(seed=seed, kind="damped", arm=arm, dur=3.5)), SR, 2.0)
        out: dict[str, Any] = {"tuning": rec}
        if tu is not None:
            for kind in ("damped", "reshuffled"):
                out[kind] = hear(tu, ln.render(ln.Scene(seed=seed + 7, kind=kind, arm=arm, rate_hz=1010.0)))
        return out

    for arm in (1, 2):
        yield f"line: arm {arm}", lambda a=arm: line(a, 20 + a)

    def alien(joint: str) -> dict[str, Any]:
        x = al.recording(joint, 1000.0, 2.0, 3.0, seed=1, knocks=False, babble=False)
        tu, rec = tuned(x, SR, 2.0)
        out: dict[str, Any] = {"tuning": rec}
        if tu is not None:
            out["heard"] = hear(tu, al.recording(joint, 1090.0, 1.7, 2.6, seed=9, gain_db=-6.0))
        return out

    for j in ("A",) if quick else ("A", "B", "C"):
        yield f"alien: {j}", lambda j=j: alien(j)

    def shaped(share: float, whistle: float | None) -> dict[str, Any]:
        tu, rec = tuned(sh.render(sh.Arm(dull_share=share, seed=3)), SR, 2.0)
        out: dict[str, Any] = {"tuning": rec}
        if tu is not None:
            out["heard"] = hear(tu, sh.render(sh.Arm(dull_share=share, whistle_db=whistle, seed=8)))
        return out

    for share, whistle in ((0.0, None), (0.2, 0.0)):
        yield f"shaped: {share} {whistle}", lambda s=share, w=whistle: shaped(s, w)


def sim_cases(quick: bool) -> Iterator[Case]:
    def joint(j: int) -> dict[str, Any]:
        x, sr = render_traverse_recording(j, 1000.0, 2.0, 3.5, seed=11)
        tu, rec = tuned(x, sr, 2.0, joint=j)
        band = tune_band(x, sr, 2.0, joint=j)
        band_abs = tune_band(x, sr, 2.0, joint=j, relative=False)
        out: dict[str, Any] = {"tuning": rec, "band": plain(band.to_dict()), "band_abs": plain(band_abs.to_dict())}
        assert tu is not None
        for k, rate in enumerate((800.0, 1100.0, 1300.0)[: 1 if quick else 3]):
            y, _ = render_traverse_recording(
                j, rate, 1.3 + 0.1 * k, 2.6, seed=5000 + 10 * j + k, gain_db=3.0, babble=True, knocks_per_min=30.0
            )
            out[f"stop {k}"] = hear(tu, y)
            out[f"band {k}"] = hear(band, y, late=False)
            out[f"band_abs {k}"] = hear(band_abs, y, late=False)
        y, _ = render_traverse_recording(j, 1150.0, 1e12, 10.0 if quick else 40.0, seed=7000 + j, babble=True)
        out["no stop"] = hear(tu, y)
        for block in (128, 777, 4096, 1 << 16):
            out[f"block {block}"] = hear(tu, y[: 3 * SR], block=block)
        return out

    for j in (1, 2, 3):
        yield f"sim: joint {j}", lambda j=j: joint(j)


def session_cases(quick: bool) -> Iterator[Case]:
    """Several stops in one recording (the re-arming), and pauses between traverses (a pause is not a stop)."""

    def session(joint: str, gaps: list[float], rates: list[float], pause_in: bool) -> dict[str, Any]:
        base = bs.Scene(joint, 1000.0, 2.0, 3.0, seed=1 if joint == "P" else 2)
        tu, rec = tuned(*bs.render(base), 2.0, seed=0)
        assert tu is not None
        room = np.random.default_rng(5)
        parts: list[np.ndarray] = []
        for k, rate in enumerate(rates):
            if k:
                parts.append((10 ** (-65 / 20) * room.standard_normal(int(gaps[k - 1] * SR))).astype(np.float32))
            y = bs.render(bs.variant(base, seed=40 + k, stop_at=1.5, dur=2.5, rate=rate))[0]
            if pause_in and k == 0:  # the stepping stops 1.0 s in for 0.6 s, then resumes
                y = np.concatenate((y[: SR], (10 ** (-65 / 20) * room.standard_normal(int(0.6 * SR))), y[SR:]))
            parts.append(np.asarray(y, np.float32))
        return {"tuning": rec, "heard": hear(tu, np.concatenate(parts).astype(np.float32))}

    yield "session: P three stops", lambda: session("P", [0.0, 0.4], [1000.0, 1040.0, 960.0], False)
    yield "session: Q with a pause", lambda: session("Q", [0.8], [1000.0, 1030.0], True)
    if not quick:
        yield "session: P pause and gaps", lambda: session("P", [1.5, 0.0], [990.0, 1000.0, 1045.0], True)


def vibration_cases(quick: bool, tmp: Path) -> Iterator[Case]:
    def vib() -> dict[str, Any]:
        import test_audio_vibration as tv

        tv._csv(tmp / "train.csv", tv.accel(1000.0, 2.0, 3.0, seed=1), with_time=False)
        tv._csv(tmp / "test.csv", tv.accel(1080.0, 1.4, 2.4, seed=2, gain=0.5), with_time=True)
        x, sr = read_vibration(tmp / "train.csv")
        tu, rec = tuned(x, sr, 2.0)
        out: dict[str, Any] = {"tuning": rec}
        if tu is not None:
            y, _ = read_vibration(tmp / "test.csv")
            out["heard"] = hear(tu, y)
        return out

    yield "vibration: 25 kHz", vib


def cases(quick: bool, tmp: Path) -> Iterator[Case]:
    yield from battery_cases(quick)
    yield from modal_cases(quick)
    yield from arrival_cases(quick)
    yield from other_generator_cases(quick)
    yield from sim_cases(quick)
    yield from session_cases(quick)
    yield from vibration_cases(quick, tmp)


# --- record and compare ----------------------------------------------------------------------------------------------
def run_all(quick: bool, only: str | None) -> dict[str, Any]:
    import tempfile

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as d:
        for name, fn in cases(quick, Path(d)):
            if only and only not in name:
                continue
            t = time.perf_counter()
            out[name] = fn()
            print(f"  {name:60s} {time.perf_counter() - t:6.1f} s", flush=True)
    return out


def diff(a: Any, b: Any, path: str, found: list[str], near: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                found.append(f"{path}/{k}: only {'before' if k in a else 'after'}")
            else:
                diff(a[k], b[k], f"{path}/{k}", found, near)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            found.append(f"{path}: {len(a)} items before, {len(b)} after")
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            diff(x, y, f"{path}[{i}]", found, near)
    elif isinstance(a, float) and isinstance(b, float) and not (isinstance(a, bool) or isinstance(b, bool)):
        if a == b or (math.isnan(a) and math.isnan(b)):
            return
        if math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-12 * max(1.0, abs(a)):
            near.append(f"{path}: {a!r} -> {b!r}")
        else:
            found.append(f"{path}: {a!r} -> {b!r}")
    elif a != b:
        found.append(f"{path}: {str(a)[:200]!r} -> {str(b)[:200]!r}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("record", "compare"))
    ap.add_argument("path", type=Path)
    ap.add_argument("--quick", action="store_true", help="a subset (about a fifth)")
    ap.add_argument("--only", help="only the cases whose name holds this")
    ap.add_argument("--save", type=Path, help="compare: also write what was heard now to this file (to compare later)")
    args = ap.parse_args()
    t = time.perf_counter()
    got = run_all(args.quick, args.only)
    print(f"{len(got)} cases in {time.perf_counter() - t:.0f} s")
    if args.mode == "record":
        args.path.write_text(json.dumps(got, indent=1) + "\n", encoding="utf-8")
        print(f"recorded {args.path}")
        return 0
    if args.save is not None:
        args.save.write_text(json.dumps(got, indent=1) + "\n", encoding="utf-8")
    ref = json.loads(args.path.read_text(encoding="utf-8"))
    found: list[str] = []
    near: list[str] = []
    per_case: dict[str, int] = {}
    for name, rec in got.items():
        if name not in ref:
            found.append(f"{name}: not in the reference")
            continue
        before = len(found)
        diff(ref[name], json.loads(json.dumps(rec)), name, found, near)
        if len(found) > before:
            per_case[name] = len(found) - before
    for name, n in per_case.items():
        print(f"DIFFERS  {name}: {n} values")
    for line in found[:60]:
        print("DIFFERS  " + line)
    for line in near[:20]:
        print("within 1e-12  " + line)
    print(
        f"{len(got)} cases compared: {len(found)} differences, {len(near)} values within 1e-12, "
        f"the rest bit-identical"
    )
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
