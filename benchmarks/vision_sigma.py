"""Is a fix's sigma a calibrated standard deviation? Sigma against the true error, with the sigma rule lifted.

Every candidate the tracker judges (near the last fix and in the whole frame) is recorded with its
standard deviation (``sigma``: ``max(sigma_floor, sigma_factor * Refinement.sigma)``, px), the
verdict of every other rule (``TipTracker._judge`` wrapped on the class; nothing in the tracker
changed) and its distance from the truth. With ``--lift`` the limits ``max_sigma`` and
``reacquire_sigma`` are raised 20-fold, so that the candidates the sigma rule refuses go on to
the other rules and their error is seen (the tracker's state then differs from the real one's
after such a frame: a counterfactual, for the distribution only).

Printed: per set, the visible tips refused and the fixes more than 3 px off; then over every
candidate all other rules take on a visible tip, by the tip's width and sigma: how many, how
many more than 3 px off, the largest error and the quantiles of ``error / sigma``.

Run: ``.venv/bin/python benchmarks/vision_sigma.py [--lift] [--scenes] [FRAMES]`` (own sets:
plain seeds 0-2, lobed, lobed wide, flake, flake wide, FRAMES each, default 400; ``--scenes``:
the third generator's seeds 0 and 1 and blunt tips 12-22 px, seed 2, default 300).
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "support"), str(ROOT / "src")]
os.environ.setdefault("OMP_NUM_THREADS", "1")

from occlusion_scenes import scene_benchmark  # noqa: E402
from vision_own import flake_benchmark, lobed_benchmark, own_benchmark  # noqa: E402

from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.template import TemplateError, TrackerParams  # noqa: E402
from stickslip.vision.track import Fix, TipTracker  # noqa: E402

RECORD: list[dict[str, Any]] = []
_JUDGE = TipTracker._judge


def _judge(self: TipTracker, cand: Any, image: Any, reacquire: bool = False) -> Any:
    res, c2 = _JUDGE(self, cand, image, reacquire)
    r = c2.ref
    RECORD.append({"x": r.x, "y": r.y, "sigma": max(self.params.sigma_floor, self.params.sigma_factor * r.sigma),
                   "taken": isinstance(res, Fix), "reacquire": reacquire})
    return res, c2


def _sets(n: int, scenes: bool) -> dict[str, Callable[[], Any]]:
    if scenes:
        return {"scenes 0": lambda: scene_benchmark(n, 30, seed=0, size=256, widths=(6.0, 22.0)),
                "scenes 1": lambda: scene_benchmark(n, 30, seed=1, size=256, widths=(6.0, 22.0)),
                "blunt 2": lambda: scene_benchmark(n, 30, seed=2, size=256, widths=(12.0, 22.0))}
    wide = {"seed": 1, "size": 256, "widths": (14.0, 18.0), "looks": ("optical",)}
    out: dict[str, Callable[[], Any]] = {
        f"plain {s}": (lambda s=s: own_benchmark(n, 40, seed=s, size=256)) for s in (0, 1, 2)}
    out.update({"lobed": lambda: lobed_benchmark(n, 40, seed=0, size=256),
                "lobed wide": lambda: lobed_benchmark(n, 40, **wide),
                "flake": lambda: flake_benchmark(n, 40, seed=0, size=256),
                "flake wide": lambda: flake_benchmark(n, 40, **wide)})
    return out


def run(name: str, seqs: Any, params: TrackerParams) -> list[tuple[float, float, float]]:
    """Track one set; print its refusals and wrong fixes; (sigma, error, tip width) of the candidates every
    other rule takes on visible tips."""
    rows: list[tuple[float, float, float]] = []
    visible = refused = wrong = 0
    for seq in seqs:
        # the own renderer's frames are read as files are; the third generator's are the tracker's floats already
        images = [as_image(f.image) if hasattr(seq, "look") else f.image for f in seq.frames]
        try:
            t = TipTracker(images[0], seq.frames[0].tip, params)
        except TemplateError:
            continue
        for f, img in zip(seq.frames[1:], images[1:], strict=True):
            RECORD.clear()
            r = t.update(img)
            tx, ty = f.tip
            visible += f.kind == "visible"
            refused += f.kind == "visible" and not isinstance(r, Fix)
            wrong += isinstance(r, Fix) and math.hypot(r.x - tx, r.y - ty) > 3.0
            rows += [(c["sigma"], math.hypot(c["x"] - tx, c["y"] - ty), seq.width_px) for c in RECORD
                     if c["taken"] and math.isfinite(c["x"])]
    print(f"{name:>11}: {refused} of {visible} visible tips refused, {wrong} fixes more than 3 px off")
    return rows


def table(rows: list[tuple[float, float, float]]) -> None:
    """The candidates by tip width and sigma: count, more than 3 px off, largest error, error/sigma quantiles."""
    s, e, w = np.array(rows).T
    for lo, hi in ((0, 10), (10, 14), (14, 23)):
        for sl, sh in ((0.0, 1.0), (1.0, 1.5), (1.5, 2.0), (2.0, math.inf)):
            m = (w >= lo) & (w < hi) & (s > sl) & (s <= sh)
            if m.any():
                q = np.percentile(e[m] / s[m], [50, 90, 99])
                print(f"  tip {lo:2d}-{hi:2d} px, sigma {sl:.1f}-{sh:<4.1f} px: {int(m.sum()):4d}, "
                      f"{int(np.sum(e[m] > 3.0)):3d} > 3 px, largest {e[m].max():7.2f} px; "
                      f"error/sigma 50/90/99 % {q[0]:.2f} {q[1]:.2f} {q[2]:.2f}")


def main(argv: list[str]) -> None:
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(argv, ["--scenes", "--lift"], __doc__)
    n = next((int(a) for a in argv if a.isdigit()), 300 if "--scenes" in argv else 400)
    params = TrackerParams()
    if "--lift" in argv:
        params = replace(params, max_sigma=20 * params.max_sigma, reacquire_sigma=20 * params.reacquire_sigma)
    TipTracker._judge = _judge  # type: ignore[method-assign]
    rows: list[tuple[float, float, float]] = []
    for name, make in _sets(n, "--scenes" in argv).items():
        rows += run(name, make(), params)
    table(rows)


if __name__ == "__main__":
    main(sys.argv[1:])
