"""Where the tracker's position error comes from: the own renderer's frames with one factor switched off at a time.

The own renderer's plain sets (``tests/support/vision_own.py``'s ``own_benchmark``, seed
``SEED``, 256 x 256, sequences of 40 frames; the same motion, widths, looks, photons and
events in every run) rendered with one of the scene's factors switched off, tracked by
:class:`~stickslip.vision.track.TipTracker` from the first frame's true tip, and each
visible tip's fix compared with the truth. The factors (the renderer patched, the
tracker not touched):

* ``noise``: no shot noise and no SEM line jitter (infinite photons), every frame;
* ``template-noise``: the template's values from the first frame without its noise (its mask,
  weights, noise level and the rest learnt from the noisy first frame, as the tracker does);
* ``ground``: a flat substrate (its median: no texture, no dust);
* ``texture``, ``dust``: the substrate's texture alone flat (its dust kept), or its dust alone left out;
* ``template-ground``: the first frame (the template's) on flat ground, the others on the substrate;
* ``vignetting``: even illumination (its mean over the field);
* ``drift``: the substrate does not drift under the needle;
* ``turn``: the needle keeps the first frame's direction (the tip still moves as it did);
* ``blur``: the needle's blur stays the first frame's (frames far out of focus stay so);
* ``all``: every factor above at once (the fit's floor on this renderer);
* ``a+b``: the factors ``a`` and ``b`` off; ``only:a+b``: every factor off but ``a`` and ``b``;
  ``only:a/c``: every factor off but ``a``, and ``c`` (one of the parts) off too.

Printed for each: visible tips fixed and refused, fixes more than 3 px off, the median and
95th percentile error, the error's component along the needle's axis (+: behind the tip) and
across it, each as mean (bias) and standard deviation, and the root mean square of the
sequences' mean error vectors (a per-sequence offset: the template's) against the spread about
them.

Run: ``.venv/bin/python benchmarks/vision_ablation.py [FRAMES [SEED]] [--only f1,f2] [--by-sequence]
[--params name=value,...] [--average N[,anchor]]`` (default 200 frames, seed 0; ``--params`` changes the
tracker's :class:`~stickslip.vision.template.TrackerParams`; ``--average`` tracks with a template averaged
over the first frame and the next ``N`` fixed ones (``_Averaging``), its apex moved by a fit to the first
frame with ``anchor``).
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "support"), str(ROOT / "src")]
os.environ.setdefault("OMP_NUM_THREADS", "1")

import vision_own  # noqa: E402

from stickslip.sim.camera import SimScene, _substrate  # noqa: E402
from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.refine import refine, steepest  # noqa: E402
from stickslip.vision.template import TemplateError, TrackerParams, _window  # noqa: E402
from stickslip.vision.track import Fix, TipTracker, _Candidate, _copy_terms, _downsample  # noqa: E402

FACTORS = ("noise", "template-noise", "ground", "vignetting", "drift", "turn", "blur")
EXTRA = ("texture", "dust", "template-ground")
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
        made: list[Ablated] = []

        def __init__(self, settings: Any) -> None:
            super().__init__(settings)
            Ablated.made.append(self)
            self.clean_first: NDArray[np.float64] | None = None
            self._flat = float(np.median(self.substrate))
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
                   flakes: Any = (), droplets: Any = ()) -> NDArray[np.float64]:
            if self._first is None:
                self._first = (np.asarray(direction, dtype=float), float(sigma))
            if "drift" in off:
                shift = None
            if "turn" in off:
                direction = self._first[0]
            if "blur" in off and sigma < 5.0:
                sigma = self._first[1]
            quiet = "noise" in off
            if "template-noise" in off and self._count == 0 and not quiet:  # the first frame without its noise too
                kept = self.rng
                self.rng = _NoNoise()  # type: ignore[assignment]
                try:
                    self.clean_first = super().render(tip_px, direction, sigma, shift, foreshortening)
                finally:
                    self.rng = kept
            self._count += 1
            kept, ground = self.rng, self.substrate
            if quiet:
                self.rng = _NoNoise()  # type: ignore[assignment]
            if "template-ground" in off and self._count == 1:
                self.substrate = np.full_like(ground, self._flat)
            try:
                return super().render(tip_px, direction, sigma, shift, foreshortening, particles, lobed, flakes,
                                      droplets)
            finally:
                self.rng, self.substrate = kept, ground

    return Ablated


def _denoised(t: TipTracker, clean: NDArray[np.float64], tip: tuple[float, float]) -> None:
    """Give ``t`` the template's values from ``clean`` (the first frame without its noise): its mask, weights,
    noise level and everything learnt from the noisy frame stay."""
    win, _ = _window(clean, int(round(tip[0])), int(round(tip[1])), t.params.half_window)
    _new_template(t, win, 0.0)


def _new_template(t: TipTracker, win: NDArray[np.float64], noise2: float) -> None:
    """``TipTracker.__init__``'s template parts made again from the window ``win`` (grey; the tip at the template's
    apex), whose noise variance is ``noise2`` times the first frame's; the mask, weights and the rules' models
    stay the first frame's."""
    p, tpl = t.params, t.template
    s0 = p.template_blur
    tpl.bank = [ndimage.gaussian_filter(win, math.hypot(s0, b), mode="nearest") for b in p.blur_bank]
    _refresh(t)
    t._coarse = [_downsample(b, p.coarse_factor) for b in tpl.bank]
    t._fft = {}
    t._bank_noise2 = [noise2 * tpl.noise**2 / (4.0 * math.pi * (s0 * s0 + b * b)) for b in p.blur_bank]
    t._spec_noise2 = [t._bank_noise2[k] for k, _, _ in t._spec]


class _Averaging(TipTracker):
    """A tracker whose template is made again, once, from the first frame's window and the next ``AVERAGE[0]``
    fixed frames' fitted with the sharp copy (turned back by the fit's turn, brought to the first frame's
    brightness and contrast over the template's weights, averaged): the template's noise variance divided by
    ``AVERAGE[0] + 1``. With ``AVERAGE[1]`` the averaged template is fitted to the first frame and its apex moved
    by what that fit says (the averaged frames' registration carried the old template's bias)."""

    def __init__(self, first: NDArray[np.float64], tip: tuple[float, float],
                 params: TrackerParams = TrackerParams()) -> None:
        super().__init__(first, tip, params)
        h = params.half_window
        win, inside = _window(first, int(round(tip[0])), int(round(tip[1])), h)
        self._win0 = win if inside.all() else None
        self._first_frame, self._tip0 = first, (float(tip[0]), float(tip[1]))
        self._acc: list[NDArray[np.float64]] = []

    def _accept(self, fix: Fix, cand: _Candidate, image: NDArray[np.float64]) -> Fix:
        out = super()._accept(fix, cand, image)
        n = AVERAGE[0]
        if self._win0 is None or len(self._acc) >= n or cand.level != 0:
            return out
        ref, tpl = cand.ref, self.template
        yy, xx = np.mgrid[0 : self._win0.shape[0], 0 : self._win0.shape[1]].astype(float)
        rx, ry = xx - tpl.apex[0], yy - tpl.apex[1]
        c, s = math.cos(ref.theta), math.sin(ref.theta)
        xs, ys = c * rx - s * ry + ref.x, s * rx + c * ry + ref.y
        if xs.min() < 0 or ys.min() < 0 or xs.max() > image.shape[1] - 1 or ys.max() > image.shape[0] - 1:
            return out
        back = ndimage.map_coordinates(image, [ys, xs], order=1, mode="nearest")
        sw = np.sqrt(tpl.weights.ravel())
        a, b = np.linalg.lstsq(np.stack([back.ravel(), np.ones(back.size)], 1) * sw[:, None],
                               self._win0.ravel() * sw, rcond=None)[0]
        self._acc.append(a * back + b)
        if len(self._acc) == n:
            _new_template(self, (self._win0 + sum(self._acc)) / (n + 1), 1.0 / (n + 1))
            if AVERAGE[1]:
                self._anchor()
        return out

    def _anchor(self) -> None:
        """Move the template's apex to where the averaged template puts the first frame's tip."""
        x0, y0 = self._tip0
        ref = refine(self._patch({}, self._first_frame, x0, y0, 0.0), self._steep[0], (x0, y0), 0.0,
                     correlation=self.params.sigma_factor)
        if not (ref.converged and math.hypot(ref.x - x0, ref.y - y0) < 2.0):
            return
        c, s = math.cos(ref.theta), math.sin(ref.theta)
        dx, dy = x0 - ref.x, y0 - ref.y
        tpl = self.template
        tpl.apex = (tpl.apex[0] + c * dx + s * dy, tpl.apex[1] - s * dx + c * dy)
        _new_template(self, tpl.bank[0], self._bank_noise2[0] / max(self._bank_noise2[0], 1e-300) / (AVERAGE[0] + 1)
                      ) if False else _refresh(self)


def _refresh(t: TipTracker) -> None:
    """The fit's parts of ``t`` made again for its template's (moved) apex."""
    p, tpl = t.params, t.template
    s0 = p.template_blur
    t._steep = [steepest(tpl.bank[k], tpl.apex, w, thin=math.hypot(s0, abs(b)) >= p.thin_blur, lap_blur=p.lap_blur)
                for (k, _, b), w in zip(t._spec, tpl.level_weights, strict=True)]
    widest = int(np.argmax([float(w.sum()) for w in tpl.level_weights]))
    t._select = t._steep[widest]
    t._bank_sel = [b[t._select.keep] for b in tpl.bank]
    t._bank_terms = [_copy_terms(b, t._select.w, float(t._select.w.sum())) for b in t._bank_sel]


def _split(fix: Fix, tip: tuple[float, float], shaft: tuple[float, float]) -> tuple[float, float]:
    """The error along the axis (+: behind the tip) and across it, px (as ``bench_vision --error-split``)."""
    c, s = math.cos(fix.angle), math.sin(fix.angle)
    ux, uy = c * shaft[0] - s * shaft[1], s * shaft[0] + c * shaft[1]
    ex, ey = fix.x - tip[0], fix.y - tip[1]
    return ex * ux + ey * uy, -ex * uy + ey * ux


def run(off: frozenset[str], n_frames: int, seed: int) -> dict[str, float]:
    """Track the plain set with ``off`` switched off; the summary numbers."""
    scene = ablated(off)
    setattr(vision_own, "SimScene", scene)  # noqa: B010 (the module's renderer replaced for this run)
    try:
        seqs = vision_own.own_benchmark(n_frames, 40, seed=seed, size=256)
    finally:
        setattr(vision_own, "SimScene", SimScene)  # noqa: B010
    clean = [getattr(m, "clean_first", None) for m in scene.made]  # type: ignore[attr-defined]
    rows: list[tuple[int, float, float, float, float]] = []
    refused = bad = 0
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            tracker = (_Averaging if AVERAGE[0] > 0 else TipTracker)(images[0], seq.frames[0].tip, PARAMS)
        except TemplateError:
            continue
        if clean[i] is not None:
            _denoised(tracker, as_image(clean[i]), seq.frames[0].tip)
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
PARAMS = TrackerParams()
AVERAGE = (0, False)
"""``--average N[,anchor]``: :class:`_Averaging`'s frames and whether it moves the apex (0: the plain tracker)."""


def main(argv: list[str]) -> None:
    global BY_SEQUENCE, PARAMS, AVERAGE
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(argv, ["--by-sequence", "--params", "--average", "--only"], __doc__)
    BY_SEQUENCE = "--by-sequence" in argv
    argv = [a for a in argv if a != "--by-sequence"]
    if "--params" in argv:  # the tracker's parameters changed: name=value,name=value
        k = argv.index("--params")
        PARAMS = replace(PARAMS, **{n: type(getattr(PARAMS, n))(v) for n, v in
                                    (kv.split("=") for kv in argv[k + 1].split(","))})
        argv = argv[:k] + argv[k + 2:]
    if "--average" in argv:
        k = argv.index("--average")
        n, _, anchor = argv[k + 1].partition(",")
        AVERAGE = (int(n), anchor == "anchor")
        argv = argv[:k] + argv[k + 2:]
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
        if name.startswith("only:"):  # every factor off but these; after "/", extra ones off
            keep, _, extra = name[5:].partition("/")
            off = frozenset(FACTORS) - frozenset(keep.split("+")) | frozenset(extra.split("+")) - {""}
        else:
            off = frozenset(FACTORS if name == "all" else () if name == "none" else name.split("+"))
        r = run(off, n_frames, seed)
        print(f"{name:<15} {r['fixed']:>5.0f} {r['refused']:>5.0f} {r['bad']:>4.0f} {r['median']:>6.3f} "
              f"{r['p95']:>5.2f} {r['along']:>+6.2f} {r['along_sd']:>5.2f} {r['across']:>+6.2f} "
              f"{r['across_sd']:>5.2f} {r['seq_rms']:>7.2f} {r['within']:>6.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
