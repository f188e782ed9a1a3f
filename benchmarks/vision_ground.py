"""What the ground under the needle does to the tracker: the rules it trips and its share of the fit's weights.

The own plain set (``own_benchmark``, seed ``SEED``, 256 x 256, 40 frames a sequence) rendered twice by
``vision_ablation``'s patched renderer: as it is, and with the ground flat (its median: no texture, no dust;
the same motion, looks, photons and events). Both are tracked with ``vision_vetoes``' recording wrapper. For
every visible tip refused on the real ground but fixed on the flat one, the refusal's reason (the tracker's)
and the rules its good candidates (within 3 px of the truth) fail, with their margins ``d``.

Printed too: both runs' median and 95th percentile error of the visible tips fixed, and over the tips fixed in
both; the first candidate of each frame the ground made refused (its error and reported sigma).

The ground's share of the template: the first frame rendered again without noise three times: on its ground,
on the flat one, and on the flat one without the needle. In the template window, the first less the second is
the ground's image (``g``: with the needle's cover over it), the second less the third the needle's (``n``; a
pixel is needle where ``|n|`` is at least 5 % of its largest). Printed per sequence (look, tip width, photons):
the share of the fit's weights (``weights``, the sharp copy's) on ground pixels, the ground's weighted
variance against the needle's (``sum w (g - g_w)² / sum w (n - n_w)²``: how much of the template is frame 0's
ground, which a moved needle does not carry along), the tips refused by the ground, the median error on each
ground and the median reported sigma of the frames' nearest good candidates on each.

Run: ``.venv/bin/python benchmarks/vision_ground.py [FRAMES [SEED]] [--params name=value,...]``
(default 400 frames, seed 0).
"""

from __future__ import annotations

import math
import os
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "benchmarks"), str(ROOT / "tests" / "support"), str(ROOT / "src")]
os.environ.setdefault("OMP_NUM_THREADS", "1")

import vision_ablation  # noqa: E402
import vision_own  # noqa: E402
import vision_vetoes  # noqa: E402

from stickslip.sim.camera import SimScene  # noqa: E402
from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.template import TemplateError, TrackerParams, _window  # noqa: E402
from stickslip.vision.track import Fix, TipTracker  # noqa: E402

PARAMS = TrackerParams()
SEQS: list[Any] = []


def _scene(off: frozenset[str]) -> type[SimScene]:
    """The ablated renderer, keeping the first frame's render arguments."""
    base = vision_ablation.ablated(off)

    class Keeping(base):  # type: ignore[valid-type,misc]
        def render(self, *args: Any, **kw: Any) -> Any:
            if not hasattr(self, "first_args"):
                self.first_args = (args, kw)
            return super().render(*args, **kw)

    return Keeping


def track(off: frozenset[str], n: int, seed: int) -> tuple[dict[tuple[int, int], Any], list[Any], list[Any]]:
    """Track the set; each visible frame's result, the sequences, the scenes and the trackers."""
    scene = _scene(off)
    vision_own.SimScene = scene  # type: ignore[attr-defined]
    try:
        seqs = vision_own.own_benchmark(n, 40, seed=seed, size=256)
    finally:
        vision_own.SimScene = SimScene  # type: ignore[attr-defined]
    out: dict[tuple[int, int], Any] = {}
    trackers: list[Any] = []
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            t = TipTracker(images[0], seq.frames[0].tip, PARAMS)
        except TemplateError:
            trackers.append(None)
            continue
        trackers.append(t)
        for k, (f, img) in enumerate(zip(seq.frames[1:], images[1:], strict=True), start=1):
            vision_vetoes.TRUTH.update(set=str(sorted(off)), tip=f.tip, kind=f.kind, cause=f.cause,
                                       width=seq.width_px, frame=(i, k))
            res = t.update(img)
            if f.kind == "visible":
                e = math.hypot(res.x - f.tip[0], res.y - f.tip[1]) if isinstance(res, Fix) else math.nan
                out[(i, k)] = (res, e)
    SEQS[:] = seqs
    return out, scene.made, trackers  # type: ignore[attr-defined]


def _bare(needle: Any) -> Any:
    """A scene's ``_needle`` that draws no needle (its arrays' shapes kept)."""
    return lambda *a: tuple(np.zeros_like(v) for v in needle(*a))


def ground_share(scenes: list[Any], seqs_trackers: list[Any]) -> list[tuple[float, float]]:
    """Per sequence: the share of the sharp copy's weights on ground pixels, and the ground's weighted variance
    against the needle's in the template window."""
    rows = []
    for sc, t in zip(scenes, seqs_trackers, strict=False):
        if t is None:
            rows.append((math.nan, math.nan))
            continue
        args, kw = sc.first_args
        kept_rng, kept_ground, kept_needle = sc.rng, sc.substrate, sc._needle
        sc.rng = vision_ablation._NoNoise()
        flat_ground = np.full_like(kept_ground, float(np.median(kept_ground)))
        try:
            full = np.asarray(SimScene.render(sc, *args, **kw), dtype=float)
            sc.substrate = flat_ground
            flat = np.asarray(SimScene.render(sc, *args, **kw), dtype=float)
            sc._needle = _bare(kept_needle)
            bare = np.asarray(SimScene.render(sc, *args, **kw), dtype=float)
        finally:
            sc.rng, sc.substrate, sc._needle = kept_rng, kept_ground, kept_needle
        tip = args[0]
        h = t.params.half_window
        at = (int(round(tip[0])), int(round(tip[1])))
        wf, _ = _window(as_image(flat), at[0], at[1], h)
        wg, _ = _window(as_image(full), at[0], at[1], h)
        wb, _ = _window(as_image(bare), at[0], at[1], h)
        nd = wf - wb
        needle = np.abs(nd) >= 0.05 * float(np.abs(nd).max())
        g = wg - wf
        w = t.template.weights
        sw = float(w.sum())
        gv = float((w * (g - (w * g).sum() / sw) ** 2).sum())
        nv = float((w * (nd - (w * nd).sum() / sw) ** 2).sum())
        rows.append((float(w[~needle].sum()) / sw, gv / max(nv, 1e-300)))
    return rows


def _sigmas(recs: list[Any]) -> dict[int, float]:
    """Per sequence, the median reported sigma (px) of each visible frame's nearest candidate within 3 px."""
    best: dict[tuple[int, int], Any] = {}
    for r in recs:
        if r["kind"] == "visible" and r["error"] <= 3.0 and (
                r["frame"] not in best or r["error"] < best[r["frame"]]["error"]):
            best[r["frame"]] = r
    out: dict[int, list[float]] = {}
    for (i, _), r in best.items():
        out.setdefault(i, []).append(r["sigma"])
    return {i: float(np.median(v)) for i, v in out.items()}


def main(argv: list[str]) -> None:
    global PARAMS
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(argv, ["--params"], __doc__)
    if "--params" in argv:
        k = argv.index("--params")
        PARAMS = replace(PARAMS, **{n: type(getattr(PARAMS, n))(v) for n, v in
                                    (kv.split("=") for kv in argv[k + 1].split(","))})
        argv = argv[:k] + argv[k + 2:]
    numbers = [int(a) for a in argv if a.isdigit()]
    n = numbers[0] if numbers else 400
    seed = numbers[1] if len(numbers) > 1 else 0
    TipTracker._judge = vision_vetoes._judge  # type: ignore[method-assign]
    real, scenes, trackers = track(frozenset(), n, seed)
    start = len(vision_vetoes.RECORD)
    flat, _, _ = track(frozenset({"ground"}), n, seed)
    recs = vision_vetoes.RECORD[:start]
    sig_real = _sigmas(recs)
    sig_flat = _sigmas(vision_vetoes.RECORD[start:])
    by_frame: dict[tuple[int, int], list[Any]] = {}
    for r in recs:
        by_frame.setdefault(r["frame"], []).append(r)
    ground_made = [f for f, (res, _) in real.items() if not isinstance(res, Fix) and isinstance(flat[f][0], Fix)]
    reasons = Counter(real[f][0].reason for f in ground_made)
    rules: Counter[str] = Counter()
    alone: Counter[str] = Counter()
    margins: dict[str, list[float]] = {}
    no_good = 0
    for f in ground_made:
        good = [r for r in by_frame.get(f, []) if r["error"] <= 3.0]
        if not good:
            no_good += 1
            continue
        best = min(good, key=lambda r: r["error"])
        fails = [k for k, v in best["d"].items() if v > 0]
        rules.update(fails)
        if len(fails) == 1:
            alone[fails[0]] += 1
        for k in fails:
            margins.setdefault(k, []).append(best["d"][k])
    refused_real = sum(not isinstance(r, Fix) for r, _ in real.values())
    refused_flat = sum(not isinstance(r, Fix) for r, _ in flat.values())
    print(f"seed {seed}, {n} frames: visible {len(real)}; refused real ground {refused_real}, flat {refused_flat}; "
          f"refused on the real ground only {len(ground_made)}")
    for name, res in (("real", real), ("flat", flat)):
        e = np.array([v for r, v in res.values() if isinstance(r, Fix)])
        print(f"  {name} ground: median {np.median(e):.3f} px, 95th percentile {np.percentile(e, 95):.2f} px, "
              f"> 3 px {int((e > 3).sum())}")
    both = [f for f in real if isinstance(real[f][0], Fix) and isinstance(flat[f][0], Fix)]
    er, ef = np.array([real[f][1] for f in both]), np.array([flat[f][1] for f in both])
    print(f"  the {len(both)} tips fixed on both: real ground median {np.median(er):.3f} / 95th percentile "
          f"{np.percentile(er, 95):.2f} px, flat ground {np.median(ef):.3f} / {np.percentile(ef, 95):.2f} px")
    print(f"  the tracker's reasons: {dict(reasons.most_common())}")
    print(f"  no candidate within 3 px: {no_good}; the nearest good candidate fails (rule: count, median d): "
          + ", ".join(f"{k}: {c}, {np.median(margins[k]):+.2f}" for k, c in rules.most_common()))
    print(f"  one rule alone: {dict(alone.most_common())}")
    first = [by_frame[f][0] for f in ground_made if by_frame.get(f)]
    e = np.array([r["error"] for r in first])
    sg = np.array([r["sigma"] for r in first])
    if len(e):
        print(f"  their first candidates ({len(e)}): error median {np.median(e):.2f}, 95th percentile "
              f"{np.percentile(e, 95):.2f}, > 3 px {int((e > 3).sum())}; reported sigma median {np.median(sg):.2f} px")
    shares = ground_share(scenes, trackers)
    for i, (s, v) in enumerate(shares):
        seq_frames = [f for f in real if f[0] == i]
        lost = sum(1 for f in ground_made if f[0] == i)
        errs = [real[f][1] for f in seq_frames if isinstance(real[f][0], Fix)]
        med = float(np.median(errs)) if errs else math.nan
        errs_flat = [flat[f][1] for f in seq_frames if isinstance(flat[f][0], Fix)]
        med_flat = float(np.median(errs_flat)) if errs_flat else math.nan
        q = SEQS[i]
        print(f"  seq {i:2d} {q.look[:3]} {q.width_px:4.1f} px {q.photons:4.0f} ph: ground's weight share {s:.2f}, "
              f"ground/needle weighted variance {v:.3f}, "
              f"refused by the ground {lost:2d} of {len(seq_frames):2d}, "
              f"median {med:.2f} (flat {med_flat:.2f}) px, sigma "
              f"{sig_real.get(i, math.nan):.2f} (flat ground {sig_flat.get(i, math.nan):.2f}) px")
    a = np.array([s for s, _ in shares if math.isfinite(s)])
    b = np.array([v for _, v in shares if math.isfinite(v)])
    print(f"  over sequences: weight share median {np.median(a):.2f} (range {a.min():.2f}-{a.max():.2f}); "
          f"variance ratio median {np.median(b):.3f} (range {b.min():.3f}-{b.max():.3f})")


if __name__ == "__main__":
    main(sys.argv[1:])
