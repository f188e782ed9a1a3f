"""Do the tracker's vetoes, taken together, separate good candidates from wrong ones better than their AND?

Every candidate the tracker judges (near the last fix and in the whole frame) is recorded with
each rule's reading as a signed margin against its threshold (``d``: 0 on the threshold,
positive when the rule refuses, in units of the threshold: ``(reading - limit) / |limit|`` for
an upper limit, ``(limit - reading) / |limit|`` for a lower one), the tracker's verdict, what
the frame is and the candidate's distance from the true tip. ``TipTracker._judge`` is wrapped
on the class (it is called as before and its answer returned unchanged); the readings are made
again beside it, for every candidate whose fit is finite, whichever rule refused it first (the
edges, the shaft and the width included, which the tracker reads only where the rules before
them take the candidate): nothing in the tracker changed.

A candidate is *good* when its frame shows the tip (``kind == "visible"``) and it lies within
3 px of it; *wrong* otherwise (more than 3 px off, or any candidate in a frame where the tip is
occluded, out of the field or out of focus: no fix may be given there).

Printed: per set the visible tips refused and the fixes more than 3 px off; over every set, the
good candidates refused by how many rules at once and which; the wrong candidates by how many
rules catch each, and those only one rule catches (rule and margin); the good candidates one
rule refuses alone, by rule, with the margin by which they fail it and how far inside every
other rule reads. With ``--save FILE`` the records are pickled for further analysis.

Run: ``.venv/bin/python benchmarks/vision_vetoes.py [FRAMES] [--save FILE]`` (own sets: plain
seeds 0-2, lobed, lobed wide, flake, flake wide, round, round wide; ``FRAMES`` each, default 400;
``--only NAME,NAME`` some of them; ``--no-record``: the per-set counts only, the tracker not wrapped).
"""

from __future__ import annotations

import math
import os
import pickle
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "support"), str(ROOT / "src")]

from vision_own import flake_benchmark, lobed_benchmark, own_benchmark, round_benchmark  # noqa: E402

from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.shaft import check_shaft  # noqa: E402
from stickslip.vision.template import TemplateError  # noqa: E402
from stickslip.vision.track import (  # noqa: E402
    Fix,
    TipTracker,
    _as_usual,
    _front_share,
    _outline_vouches,
    _pick_level,
    _vouched_as_found,
    _width_of,
)

RECORD: list[dict[str, Any]] = []
TRUTH: dict[str, Any] = {}
_JUDGE = TipTracker._judge

HARD = ("field", "coverage", "unconverged", "top copy", "found blurred", "nothing vouches")
"""Rules read as yes or no (``d`` = +1 refuses, -1 takes): the field's edge and the template's share in it are
required refusals; the others have no threshold to be near."""


def _up(reading: float, limit: float) -> float:
    return (reading - limit) / abs(limit)


def _down(reading: float, limit: float) -> float:
    return (limit - reading) / abs(limit)


def _focus_last(t: TipTracker, cand: Any, blur: float) -> int:
    """The last fix's copy the focus step is judged against, as :func:`~stickslip.vision.track._focus_reread`
    picks it."""
    p = t.params
    last = t._level
    if abs(blur - t._spec[last][2]) <= p.max_blur_step * math.sqrt(t._since):
        return last
    view = t._last_view
    if view is None or t._last is None or not _as_usual(cand.ref.score, t._usual_mismatch()):
        return last
    scores = t._levels({}, view.frame(), t._last[0], t._last[1], t._theta)
    return _pick_level(scores, t._level, p.level_hysteresis)


def readings(t: TipTracker, cand: Any, image: np.ndarray, reacquire: bool) -> dict[str, float]:
    """Each rule's margin ``d`` on ``cand`` (see the module docstring); NaN where a reading does not exist."""
    p, r = t.params, cand.ref
    H, W = image.shape
    blur = t._spec[cand.level][2]
    d: dict[str, float] = {}
    edge = min(r.x, r.y, W - 1 - r.x, H - 1 - r.y)
    d["field"] = 1.0 if edge < p.edge_margin + 2.0 * max(blur, 0.0) else -1.0
    d["coverage"] = 1.0 if r.coverage < p.min_coverage else -1.0
    sigma = max(p.sigma_floor, p.sigma_factor * r.sigma)
    d["outliers"] = _up(r.outliers, p.occluded_fraction)
    d["front"] = _up(_front_share(t.template, cand, max(blur, 0.0)), p.front_fraction)
    d["top copy"] = 1.0 if cand.level == t._top else -1.0
    d["max blur"] = _up(blur, p.max_blur)
    d["score"] = _down(r.score, p.reacquire_score if reacquire else p.min_score)
    limit = t._mismatch_limit(p.reacquire_ratio if reacquire else p.mismatch_ratio)
    d["mismatch"] = _up(1.0 - r.score, limit)
    d["turn"] = _up(abs(r.theta), p.max_turn)
    d["unconverged"] = -1.0 if r.converged else 1.0
    d["sigma"] = _up(sigma, p.reacquire_sigma if reacquire else p.max_sigma)
    last = _focus_last(t, cand, blur)
    last_blur = t._spec[last][2]
    d["focus step"] = _up(abs(blur - last_blur), p.max_blur_step * math.sqrt(t._since))
    d["found blurred"] = 1.0 if (reacquire and t._top >= cand.level > last + 1 and blur > last_blur) else -1.0
    ec = t._edge_check({t._spec[cand.level][1]: cand.patch}, image, r, cand.level)
    nan = math.nan
    d["edge far"] = nan if ec is None else _down(ec.far, p.edge_contrast)
    d["edge shape"] = nan if ec is None else _down(ec.shape, p.edge_shape)
    d["edge near"] = nan if ec is None or ec.far <= 0 else _down(ec.near / ec.far, p.edge_near)
    sc = check_shaft(t._shaft, cand.level, image, r.x, r.y, r.theta)
    d["shaft back"] = nan if sc is None else _down(sc.back, p.edge_contrast)
    d["shaft shape"] = nan if sc is None else _down(sc.shape, p.edge_shape)
    d["taper"] = nan if sc is None else _up(abs(sc.along), p.along_limit + p.along_sigmas * sc.along_sd)
    wc, unvouched = _width_of(t._width, p, cand, image, sigma if reacquire else None)
    # as _judge: the found-again rules, then the outline, vouch where no station does
    unvouched = unvouched and not (_vouched_as_found(t, r, sigma) or _outline_vouches(t, cand, image))
    d["nothing vouches"] = 1.0 if unvouched else -1.0
    if wc is None:
        d["width"] = d["extent"] = nan
    else:
        tol = float(np.median(wc.tolerance)) if wc.tolerance else 1.0
        d["width"] = wc.excess / max(tol, 1e-6)
        d["extent"] = _up(max(wc.short), p.extent_slack) if wc.short else nan
    return d


def _judge(self: TipTracker, cand: Any, image: Any, reacquire: bool = False) -> Any:
    res, c2 = _JUDGE(self, cand, image, reacquire)
    r = cand.ref
    if math.isfinite(r.x) and math.isfinite(r.y):
        tx, ty = TRUTH["tip"]
        RECORD.append({"set": TRUTH["set"], "kind": TRUTH["kind"], "cause": TRUTH["cause"],
                       "error": math.hypot(r.x - tx, r.y - ty), "taken": isinstance(res, Fix),
                       "reason": "" if isinstance(res, Fix) else res.reason,
                       "detail": "" if isinstance(res, Fix) else res.detail, "reacquire": reacquire,
                       "width_px": TRUTH["width"], "frame": TRUTH["frame"], "score": r.score,
                       "sigma": max(self.params.sigma_floor, self.params.sigma_factor * r.sigma),
                       "usual": self._usual_mismatch(), "first mismatch": self._first_mismatch,
                       "blur": self._spec[cand.level][2], "d": readings(self, cand, image, reacquire)})
    return res, c2


def own_sets(n: int) -> dict[str, Callable[[], Any]]:
    """The own renderer's sets (development data): plain seeds 0-2, the lobed, flake and round modes (seed 0,
    tips 3-20 px, both looks) and each mode's wide bright-field set (seed 1, tips 14-18 px)."""
    wide = {"seed": 1, "size": 256, "widths": (14.0, 18.0), "looks": ("optical",)}
    out: dict[str, Callable[[], Any]] = {
        f"plain {s}": (lambda s=s: own_benchmark(n, 40, seed=s, size=256)) for s in (0, 1, 2)}
    for name, make in (("lobed", lobed_benchmark), ("flake", flake_benchmark), ("round", round_benchmark)):
        out[name] = lambda make=make: make(n, 40, seed=0, size=256)
        out[f"{name} wide"] = lambda make=make: make(n, 40, **wide)
    return out


def run(name: str, seqs: Any) -> tuple[int, int, int, list[float]]:
    """Track one set, recording; the visible tips, those refused, the fixes more than 3 px off (or in a frame
    without a visible tip) and the visible tips' errors."""
    visible = refused = wrong = 0
    errors: list[float] = []
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            t = TipTracker(images[0], seq.frames[0].tip)
        except TemplateError:
            continue
        for k, (f, img) in enumerate(zip(seq.frames[1:], images[1:], strict=True), start=1):
            TRUTH.update(set=name, tip=f.tip, kind=f.kind, cause=f.cause, width=seq.width_px, frame=(i, k))
            start = len(RECORD)
            res = t.update(img)
            for rec in RECORD[start:]:
                rec["frame fixed"] = isinstance(res, Fix)
            vis = f.kind == "visible"
            visible += vis
            refused += vis and not isinstance(res, Fix)
            if isinstance(res, Fix):
                e = math.hypot(res.x - f.tip[0], res.y - f.tip[1])
                wrong += e > 3.0 or not vis
                if vis:
                    errors.append(e)
    return visible, refused, wrong, errors


def summary(records: list[dict[str, Any]]) -> None:
    """The good candidates refused and the wrong ones caught, by how many rules and which."""
    good = [r for r in records if r["kind"] == "visible" and r["error"] <= 3.0]
    bad = [r for r in records if not (r["kind"] == "visible" and r["error"] <= 3.0)]

    def fails(r: dict[str, Any]) -> list[str]:
        return [k for k, v in r["d"].items() if v > 0]

    print(f"\n{len(records)} candidates judged: {len(good)} good (visible, <= 3 px), {len(bad)} wrong")
    g_ref = [r for r in good if not r["taken"]]
    print(f"good refused: {len(g_ref)}; by how many rules at once: "
          f"{sorted(Counter(len(fails(r)) for r in g_ref).items())}")
    single = Counter(fails(r)[0] for r in g_ref if len(fails(r)) == 1)
    print(f"  refused by one rule alone: {sum(single.values())}: {dict(single.most_common())}")
    pairs = Counter(" + ".join(sorted(fails(r))) for r in g_ref if len(fails(r)) == 2)
    print(f"  by two: {dict(pairs.most_common(12))}")
    b_taken = [r for r in bad if r["taken"]]
    print(f"wrong taken: {len(b_taken)}" + "".join(
        f"\n  {r['set']} {r['kind']} {r['cause']} {r['error']:.1f} px" for r in b_taken))
    b_ref = [r for r in bad if not r["taken"]]
    print(f"wrong refused: {len(b_ref)}; by how many rules at once: "
          f"{sorted(Counter(len(fails(r)) for r in b_ref).items())}")
    one = [r for r in b_ref if len(fails(r)) == 1]
    print(f"  caught by one rule only: {len(one)}: {dict(Counter(fails(r)[0] for r in one).most_common())}")
    for rule in sorted({fails(r)[0] for r in one} | set(single)):
        gd = [r["d"][rule] for r in g_ref if fails(r) == [rule]]
        bd = [r["d"][rule] for r in one if fails(r) == [rule]]
        gin = [max(v for k, v in r["d"].items() if k != rule and math.isfinite(v)) for r in g_ref
               if fails(r) == [rule]]
        bin_ = [max(v for k, v in r["d"].items() if k != rule and math.isfinite(v)) for r in one
                if fails(r) == [rule]]
        print(f"  {rule:>15}: good refused by it alone {len(gd):4d}, margin "
              f"{_q(gd)}, the others' largest {_q(gin)}; wrong caught by it alone {len(bd):4d}, margin "
              f"{_q(bd)}, the others' largest {_q(bin_)}")


def _q(v: list[float]) -> str:
    if not v:
        return "-"
    a = np.array(v)
    return f"{a.min():+.2f}/{np.median(a):+.2f}/{a.max():+.2f}"


def main(argv: list[str]) -> None:
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(argv, ["--save", "--only", "--no-record"], __doc__)
    n = next((int(a) for a in argv if a.isdigit()), 400)
    save = argv[argv.index("--save") + 1] if "--save" in argv else None
    only = argv[argv.index("--only") + 1].split(",") if "--only" in argv else None
    if "--no-record" not in argv:
        TipTracker._judge = _judge  # type: ignore[method-assign]
    for name, make in own_sets(n).items():
        if only and name not in only:
            continue
        visible, refused, wrong, errors = run(name, make())
        e = np.array(errors) if errors else np.array([math.nan])
        print(f"{name:>11}: {refused:3d} of {visible:4d} visible tips refused, {wrong} wrong fixes, "
              f"median {np.median(e):.3f} px, 95th percentile {np.percentile(e, 95):.3f} px", flush=True)
    if RECORD:
        summary(RECORD)
    if save:
        with open(save, "wb") as fh:
            pickle.dump(RECORD, fh)


if __name__ == "__main__":
    main(sys.argv[1:])
