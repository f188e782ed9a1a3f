"""The own sets' refused visible tips by the rule that refused them, and how far off the refused fit was.

Every own set of the outline's measurement (13 sets of 400 frames, 256 px: plain seeds 0-2; the round
mode's seeds 0, 2, 4 (tips 3-20 px, both looks) and 1, 3, 5 (bright field, 14-18 px); the lobed and flake
modes' seed 0 and their wide seed 1) is tracked with ``TipTracker._judge`` wrapped on the class (called as
before, its answer returned unchanged: nothing in the tracker changed). For each visible tip refused, the
candidate whose refusal the frame reports (the fit near the last fix; for "not found", the whole frame's
best-correlating candidate, as :func:`~stickslip.vision.track._not_found` names it) is kept with its error
along the needle's axis and across it (``bench_vision._split``: along positive behind the tip), its sigma, its
blur copy, the copy the focus step was judged against, the frames since the last fix, and, for the sigma
and focus-step refusals, every other rule's margin (``vision_vetoes.readings``: positive refuses): whether
the fit would have been taken with that rule alone lifted.

Printed: per set the visible tips, the refused by rule, the fixes more than 3 px off, median and 95th
percentile; then for the sigma (near the last fix / found again) and focus-step refusals the refused fits'
error (within 1 px, 1-3 px, beyond), along and across, and how many every other rule takes.

Run: ``PYTHONPATH=tests/support .venv/bin/python benchmarks/vision_refused.py [FRAMES] [--only NAME,NAME]
[--save FILE] [--params NAME=VALUE,...] [--micrograph] [--defocus disc]`` (``FRAMES`` default 400; set names have
a space: ``--only "plain 0,lobed"``; ``--load FILE,FILE`` reports saved runs; ``--micrograph``: the micrograph
mode's six sets instead, ``micro 1`` to ``retina 3``, 1600 frames each for track51's table; they need
scikit-image; ``--defocus disc``: the own renderer's needle blurred by the blur circle instead of the Gaussian).
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import sys
from collections import Counter
from collections.abc import Callable
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "benchmarks"), str(ROOT / "tests" / "support"), str(ROOT / "src")]

from bench_vision import _rule, _split, learnt_sequences  # noqa: E402
from vision_own import (  # noqa: E402
    flake_benchmark,
    lobed_benchmark,
    micrograph_benchmark,
    own_benchmark,
    round_benchmark,
)
from vision_vetoes import readings  # noqa: E402

from stickslip.vision.template import TrackerParams  # noqa: E402
from stickslip.vision.track import FOCUS_STEP, Fix, Lost, TipTracker  # noqa: E402

JUDGED: list[dict[str, Any]] = []
_JUDGE = TipTracker._judge
CLASSES = ("position undetermined", FOCUS_STEP)
"""The refusals whose candidates' other rules are read (sigma, the focus step)."""


def _judge(self: TipTracker, cand: Any, image: Any, reacquire: bool = False) -> Any:
    last_level, since = self._level, self._since
    res, c2 = _JUDGE(self, cand, image, reacquire)
    r = c2.ref
    rec: dict[str, Any] = {"res": res, "reacquire": reacquire, "x": r.x, "y": r.y, "theta": r.theta,
                           "score": r.score, "level": c2.level, "blur": self._spec[c2.level][2],
                           "last blur": self._spec[last_level][2], "since": since,
                           "sigma": max(self.params.sigma_floor, self.params.sigma_factor * r.sigma)}
    if isinstance(res, Lost) and any(k in res.detail for k in CLASSES) and math.isfinite(r.x):
        rec["d"] = readings(self, cand, image, reacquire)
    JUDGED.append(rec)
    return res, c2


def own_sets(n: int, defocus: str = "gaussian") -> dict[str, Callable[[], Any]]:
    """The 13 own sets (development data) the outline's round measured; ``defocus``: the needle's blur's shape."""
    wide = {"size": 256, "widths": (14.0, 18.0), "looks": ("optical",), "defocus": defocus}
    d = defocus
    out: dict[str, Callable[[], Any]] = {
        f"plain {s}": (lambda s=s: own_benchmark(n, 40, seed=s, size=256, defocus=d)) for s in (0, 1, 2)}
    for s in (0, 2, 4):
        out[f"round {s}"] = lambda s=s: round_benchmark(n, 40, seed=s, size=256, defocus=d)
    for s in (1, 3, 5):
        out[f"round wide {s}"] = lambda s=s: round_benchmark(n, 40, seed=s, **wide)  # type: ignore[arg-type]
    for name, make in (("lobed", lobed_benchmark), ("flake", flake_benchmark)):
        out[name] = lambda make=make: make(n, 40, seed=0, size=256, defocus=d)
        out[f"{name} wide"] = lambda make=make: make(n, 40, seed=1, **wide)
    return out


def micrograph_sets(n: int, defocus: str = "gaussian") -> dict[str, Callable[[], Any]]:
    """The micrograph mode's six sets (``bench_vision.py --micrograph``): ``n`` frames each, in sequences of 40."""
    return {f"{g} {s}": (lambda g=g, s=s: micrograph_benchmark(g, s, max(1, n // 40), defocus=defocus))
            for g in ("micro", "retina") for s in (1, 2, 3)}


def _reported(res: Lost, judged: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The judged candidate whose refusal ``update`` reports."""
    if res.detail.startswith("not found near the last fix; in the frame"):
        glob = [j for j in judged if j["reacquire"] and isinstance(j["res"], Lost)]
        return max(glob, key=lambda j: j["score"]) if glob else None
    same = [j for j in judged if isinstance(j["res"], Lost) and j["res"].detail == res.detail]
    return same[-1] if same else None


def run(name: str, seqs: Any, params: TrackerParams) -> list[dict[str, Any]]:
    """Track one set; a row for every visible tip (fixed or refused)."""
    rows: list[dict[str, Any]] = []
    for i, seq, t, images in learnt_sequences(seqs, params):
        for k, (f, img) in enumerate(zip(seq.frames[1:], images[1:], strict=True), start=1):
            JUDGED.clear()
            res = t.update(img)
            row: dict[str, Any] = {"set": name, "seq": i, "frame": k, "kind": f.kind, "width": seq.width_px,
                                   "fixed": isinstance(res, Fix)}
            if isinstance(res, Fix):
                row["error"] = math.hypot(res.x - f.tip[0], res.y - f.tip[1])
                row["along"], row["across"] = _split(res, f.tip, t.template.shaft)
                row["blur truth"], row["blur first"] = f.blur, seq.frames[0].blur
            elif f.kind == "visible":
                row["rule"] = _rule(res)
                row["detail"] = res.detail
                c = _reported(res, JUDGED)
                if c is not None and math.isfinite(c["x"]):
                    fake = Fix(c["x"], c["y"], 0.0, c["sigma"], c["blur"], c["theta"])
                    row["along"], row["across"] = _split(fake, f.tip, t.template.shaft)
                    row["error"] = math.hypot(row["along"], row["across"])
                    row.update({k2: c[k2] for k2 in ("sigma", "blur", "last blur", "since", "reacquire", "score")})
                    row["d"] = c.get("d")
                    row["blur truth"] = f.blur
                    row["blur first"] = seq.frames[0].blur
            if f.kind == "visible" or isinstance(res, Fix):
                rows.append(row)
    return rows


def report(rows: list[dict[str, Any]]) -> None:
    """Per set, then the sigma and focus-step classes' refused fits."""
    names = list(dict.fromkeys(r["set"] for r in rows))
    rules = [k for k, _ in Counter(r["rule"] for r in rows if "rule" in r).most_common()]
    print(f"{'set':<13} {'vis':>4} {'ref':>4} " + " ".join(f"{k[:9]:>9}" for k in rules) + "  >3px   med   p95")
    for name in [*names, "all"]:
        mine = [r for r in rows if name in ("all", r["set"])]
        vis = [r for r in mine if r["kind"] == "visible"]
        ref = Counter(r["rule"] for r in vis if not r["fixed"])
        e = np.array([r["error"] for r in vis if r["fixed"]] or [math.nan])
        wrong = sum(r["fixed"] and (r["kind"] != "visible" or r["error"] > 3.0) for r in mine)
        print(f"{name:<13} {len(vis):>4} {sum(ref.values()):>4} " + " ".join(f"{ref[k]:>9}" for k in rules)
              + f"  {wrong:>4} {np.median(e):.3f} {np.percentile(e, 95):.3f}")
    for label, pick in (("sigma, near the last fix", lambda r: r["rule"] == "sigma" and not r.get("reacquire")),
                        ("sigma, found again", lambda r: r["rule"] == "sigma" and r.get("reacquire")),
                        ("focus step", lambda r: r["rule"] == "focus step")):
        _class(label, [r for r in rows if "rule" in r and pick(r) and "error" in r])


def _class(label: str, rs: list[dict[str, Any]]) -> None:
    if not rs:
        print(f"\n{label}: none")
        return
    e = np.array([r["error"] for r in rs])
    al = np.array([r["along"] for r in rs])
    ac = np.array([r["across"] for r in rs])
    print(f"\n{label}: {len(rs)} refused fits; within 1 px {int(np.sum(e <= 1))}, 1-3 px "
          f"{int(np.sum((e > 1) & (e <= 3)))}, beyond 3 px {int(np.sum(e > 3))}; median {np.median(e):.2f} px; "
          f"|along| median {np.median(np.abs(al)):.2f}, |across| median {np.median(np.abs(ac)):.2f}")
    own = "sigma" if label.startswith("sigma") else "focus step"
    others = Counter()
    alone = []
    for r in rs:
        d = r.get("d") or {}
        bad = sorted(k for k, v in d.items() if k != own and math.isfinite(v) and v > 0)
        others.update(bad or ["(none: taken with this rule lifted)"])
        if not bad:
            alone.append(r)
    print(f"  other rules that also refuse: {dict(others.most_common())}")
    ea = np.array([r["error"] for r in alone] or [math.nan])
    print(f"  refused by this rule alone: {len(alone)}; within 1 px {int(np.sum(ea <= 1))}, 1-3 px "
          f"{int(np.sum((ea > 1) & (ea <= 3)))}, beyond 3 px {int(np.sum(ea > 3))}")
    print("  set, seq, frame, width, error, along, across, sigma, copy, last copy, since, frame blur (first), score,"
          " other rules")
    for r in rs:
        d = r.get("d") or {}
        bad = ",".join(sorted(k for k, v in d.items() if k != own and math.isfinite(v) and v > 0))
        print(f"  {r['set']:<12} {r['seq']:>2} {r['frame']:>2} {r['width']:5.1f} {r['error']:6.2f} {r['along']:+6.2f}"
              f" {r['across']:+6.2f} {r['sigma']:5.2f} {r['blur']:+5.1f} {r['last blur']:+5.1f} {r['since']:>2}"
              f" {r['blur truth']:4.2f} ({r['blur first']:4.2f}) {r['score']:.3f} {bad}")


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("frames", nargs="?", type=int, default=400, help="frames per set (default 400)")
    ap.add_argument("--only", help=f"sets, comma-separated, of {list(own_sets(1))}")
    ap.add_argument("--save", metavar="FILE", help="keep the refused rows (pickle) for --load")
    ap.add_argument("--load", metavar="FILE,FILE", help="report saved runs instead of tracking")
    ap.add_argument("--params", metavar="NAME=VALUE,...", help="TrackerParams fields to set (floats; a word: a string)")
    ap.add_argument("--defocus", choices=("gaussian", "disc"), default="gaussian",
                    help="the own renderer's defocus: Gaussian (default) or the blur circle of the same variance")
    ap.add_argument("--micrograph", action="store_true", help="the micrograph mode's six sets instead")
    a = ap.parse_args(argv)
    rows: list[dict[str, Any]] = []
    if a.load:
        for path in a.load.split(","):
            with open(path, "rb") as fh:
                rows += pickle.load(fh)
        report(rows)
        return
    sets = micrograph_sets(a.frames, a.defocus) if a.micrograph else own_sets(a.frames, a.defocus)
    only = a.only.split(",") if a.only else list(sets)
    unknown = [name for name in only if name not in sets]
    if unknown:
        ap.error(f"unknown sets {unknown}; of {list(sets)}")
    params = TrackerParams()
    names = {f.name for f in fields(TrackerParams)}
    for item in (a.params.split(",") if a.params else []):
        key, _, value = item.partition("=")
        if key not in names:
            ap.error(f"--params: {key!r} is not a TrackerParams field")
        try:
            params = replace(params, **{key: float(value)})
        except ValueError:
            params = replace(params, **{key: value})
    TipTracker._judge = _judge  # type: ignore[method-assign]
    for name in only:
        seqs = sets[name]()
        if not seqs:
            print(f"{name} skipped: scikit-image (the dev extra, which ships the micrographs) is missing")
            continue
        rows += run(name, seqs, params)
        print(f"{name} done", flush=True)
    report(rows)
    if a.save:
        with open(a.save, "wb") as fh:
            pickle.dump(rows, fh)


if __name__ == "__main__":
    main(sys.argv[1:])
