"""Where the tracker's position error comes from: the own renderer's frames with one factor switched off at a time.

The own renderer's plain sets (``tests/support/vision_own.py``'s ``own_benchmark``, seed
``SEED``, 256 x 256, sequences of 40 frames; the same motion, widths, looks, photons and
events in every run) rendered with one of the scene's factors switched off, tracked by
:class:`~stickslip.vision.track.TipTracker` from the first frame's true tip, and each
visible tip's fix compared with the truth. The factors (the renderer patched, the
tracker not touched):

* ``noise``: no shot noise and no SEM line jitter (infinite photons), every frame;
* ``template-noise``: the first frame (the one the template is learnt from) without noise;
* ``ground``: a flat substrate (its median: no texture, no dust);
* ``texture``, ``dust``: the substrate's texture alone flat (its dust kept), or its dust alone left out;
* ``vignetting``: even illumination (its mean over the field);
* ``drift``: the substrate does not drift under the needle;
* ``turn``: the needle keeps the first frame's direction (the tip still moves as it did);
* ``blur``: the needle's blur stays the first frame's (frames far out of focus stay so);
* ``all``: every factor above at once (the fit's floor on this renderer);
* ``a+b``: the factors ``a`` and ``b`` off; ``only:a+b``: every factor off but ``a`` and ``b``.

Printed for each: visible tips fixed and refused, fixes more than 3 px off, the median and
95th percentile error, the error's component along the needle's axis (+: behind the tip) and
across it, each as mean (bias) and standard deviation, and the root mean square of the
sequences' mean error vectors (a per-sequence offset: the template's) against the spread about
them.

Run: ``.venv/bin/python benchmarks/vision_ablation.py [FRAMES [SEED]] [--only f1,f2]``
(default 200 frames, seed 0).
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "support"), str(ROOT / "src")]
os.environ.setdefault("OMP_NUM_THREADS", "1")

import vision_own  # noqa: E402

from stickslip.sim.camera import SimScene, _substrate  # noqa: E402
from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.template import TemplateError  # noqa: E402
from stickslip.vision.track import Fix, TipTracker  # noqa: E402

FACTORS = ("noise", "template-noise", "ground", "vignetting", "drift", "turn", "blur")
EXTRA = ("texture", "dust")
"""Parts of ``ground``, not in ``all``."""


class _NoNoise:
    """Stands for the scene's noise generator: the expected counts, no jitter."""

    def poisson(self, lam: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(lam, dtype=float)

    def normal(self, loc: float, scale: float, size: Any) -> NDArray[np.float64]:
        return np.zeros(size)


def ablated(off: frozenset[str]) -> type[SimScene]:
    """A :class:`SimScene` with the factors ``off`` switched off."""

    class Ablated(SimScene):
        def __init__(self, settings: Any) -> None:
            super().__init__(settings)
            if "ground" in off:
                self.substrate = np.full_like(self.substrate, float(np.median(self.substrate)))
            elif off & {"texture", "dust"}:
                m = self.margin
                h, w = settings.height + 2 * m, settings.width + 2 * m
                # the same draws without the dust: the texture alone, the dust the difference
                texture = _substrate(h, w, settings.look, 0, np.random.default_rng([settings.seed, 7]))
                level = float(np.median(texture))
                self.substrate = (level + self.substrate - texture if "texture" in off
                                  else texture if "dust" in off else self.substrate)
            if "vignetting" in off:
                self.illumination = np.full_like(self.illumination, float(self.illumination.mean()))
            self._count = 0
            self._first: tuple[NDArray[np.float64], float] | None = None

        def render(self, tip_px: Any, direction: Any, sigma: float, shift: Any = None,
                   foreshortening: float = 1.0, particles: Any = (), lobed: Any = (),
                   flakes: Any = ()) -> NDArray[np.float64]:
            if self._first is None:
                self._first = (np.asarray(direction, dtype=float), float(sigma))
            if "drift" in off:
                shift = None
            if "turn" in off:
                direction = self._first[0]
            if "blur" in off and sigma < 5.0:
                sigma = self._first[1]
            quiet = "noise" in off or ("template-noise" in off and self._count == 0)
            self._count += 1
            kept = self.rng
            if quiet:
                self.rng = _NoNoise()  # type: ignore[assignment]
            try:
                return super().render(tip_px, direction, sigma, shift, foreshortening, particles, lobed, flakes)
            finally:
                self.rng = kept

    return Ablated


def _split(fix: Fix, tip: tuple[float, float], shaft: tuple[float, float]) -> tuple[float, float]:
    """The error along the axis (+: behind the tip) and across it, px (as ``bench_vision --error-split``)."""
    c, s = math.cos(fix.angle), math.sin(fix.angle)
    ux, uy = c * shaft[0] - s * shaft[1], s * shaft[0] + c * shaft[1]
    ex, ey = fix.x - tip[0], fix.y - tip[1]
    return ex * ux + ey * uy, -ex * uy + ey * ux


def run(off: frozenset[str], n_frames: int, seed: int) -> dict[str, float]:
    """Track the plain set with ``off`` switched off; the summary numbers."""
    vision_own.SimScene = ablated(off)  # type: ignore[misc]
    try:
        seqs = vision_own.own_benchmark(n_frames, 40, seed=seed, size=256)
    finally:
        vision_own.SimScene = SimScene  # type: ignore[misc]
    rows: list[tuple[int, float, float, float, float]] = []
    refused = bad = 0
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            tracker = TipTracker(images[0], seq.frames[0].tip)
        except TemplateError:
            continue
        for f, img in zip(seq.frames[1:], images[1:], strict=True):
            r = tracker.update(img)
            if isinstance(r, Fix):
                e = math.hypot(r.x - f.tip[0], r.y - f.tip[1])
                bad += e > 3.0
                if f.kind == "visible":
                    along, across = _split(r, f.tip, tracker.template.shaft)
                    rows.append((i, along, across, r.x - f.tip[0], r.y - f.tip[1]))
            elif f.kind == "visible":
                refused += 1
    a = np.array(rows).reshape(-1, 5)
    err = np.hypot(a[:, 1], a[:, 2])
    means = np.array([a[a[:, 0] == i, 3:].mean(axis=0) for i in np.unique(a[:, 0])])
    seq_of = {int(i): m for i, m in zip(np.unique(a[:, 0]), means, strict=True)}
    about = a[:, 3:] - np.array([seq_of[int(i)] for i in a[:, 0]])
    if BY_SEQUENCE:
        for i in np.unique(a[:, 0]).astype(int):
            m = a[:, 0] == i
            q = seqs[i]
            print(f"   seq {i} {q.look[:3]} {q.width_px:4.1f} px {q.photons:3.0f} ph: {int(m.sum()):>3} fixes, median "
                  f"{np.median(err[m]):.2f}, along {a[m, 1].mean():+.2f} sd {a[m, 1].std():.2f}, across "
                  f"{a[m, 2].mean():+.2f} sd {a[m, 2].std():.2f}")
    return {"fixed": float(len(a)), "refused": float(refused), "bad": float(bad),
            "median": float(np.median(err)), "p95": float(np.percentile(err, 95)),
            "along": float(a[:, 1].mean()), "along_sd": float(a[:, 1].std()),
            "across": float(a[:, 2].mean()), "across_sd": float(a[:, 2].std()),
            "seq_rms": float(np.sqrt(np.mean(np.sum(means**2, axis=1)))),
            "within": float(np.sqrt(np.mean(np.sum(about**2, axis=1))))}


BY_SEQUENCE = False


def main(argv: list[str]) -> None:
    global BY_SEQUENCE
    BY_SEQUENCE = "--by-sequence" in argv
    argv = [a for a in argv if a != "--by-sequence"]
    only = None
    if "--only" in argv:
        k = argv.index("--only")
        only = argv[k + 1].split(",")
        argv = argv[:k] + argv[k + 2:]
    numbers = [int(a) for a in argv if a.isdigit()]
    n_frames = numbers[0] if numbers else 200
    seed = numbers[1] if len(numbers) > 1 else 0
    runs = only or ["none", *FACTORS, "all"]
    print(f"own plain set, seed {seed}, {n_frames} frames; px; along + behind the tip")
    print(f"{'off':<15} {'fixed':>5} {'refus':>5} {'>3px':>4} {'median':>6} {'p95':>5} {'along':>6} {'sd':>5} "
          f"{'across':>6} {'sd':>5} {'seq rms':>7} {'within':>6}")
    for name in runs:
        if name.startswith("only:"):  # every factor off but these
            off = frozenset(FACTORS) - frozenset(name[5:].split("+"))
        else:
            off = frozenset(FACTORS if name == "all" else () if name == "none" else name.split("+"))
        r = run(off, n_frames, seed)
        print(f"{name:<15} {r['fixed']:>5.0f} {r['refused']:>5.0f} {r['bad']:>4.0f} {r['median']:>6.3f} "
              f"{r['p95']:>5.2f} {r['along']:>+6.2f} {r['along_sd']:>5.2f} {r['across']:>+6.2f} "
              f"{r['across_sd']:>5.2f} {r['seq_rms']:>7.2f} {r['within']:>6.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
