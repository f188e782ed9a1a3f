"""The template fit's efficiency against the noise-limited bound (Cramér-Rao), on noise-only own frames.

For a few needles of the own renderer (:class:`~stickslip.sim.camera.SimScene`: bright field and
SEM, thin and wide tips, few and many photons) on flat ground under even light (every factor of
``vision_ablation.py`` off but the shot noise and the SEM's line jitter), the tracker learns the
first frame (noisy, as it does) and the second frame (the needle moved by a non-integer step,
the same turn and blur) is drawn again and again with new noise and fitted from its true tip
(``refine`` on the sharp copy, as ``TipTracker._try`` fits it). Printed per needle, along the
needle's axis and across it (px):

* ``crb``: the Cramér-Rao bound of the tip's position for the fit's own model over the
  tracker's 41 x 41 px window: the noise-free frame's derivatives (the renderer's, by central
  differences) with respect to the two shifts, the turn about the tip, the blur, and the
  contrast and brightness planes, and the pixels' noise covariance (Poisson: the expected count;
  the SEM's line jitter shared along a scan line);
  (the fit's prior on the turn, 0.05 rad, included);
* ``crb mask``: the same over the pixels the fit weighs (its mask's support) only;
* each estimator variant's standard deviation over the draws and the bound over it
  (``eff`` = crb / sd), its bias, and the fit's own reported sigma over the actual sd
  (the covariance factor 3.5 included: above 1, the reported sigma is pessimistic).

The variants, one change at a time from the tracker's fit (``main``: the noisy first frame's
template, the needle mask's weights with the distance fall-off, the 1 px smoothing of both,
Tukey's biweight): ``clean`` the template's values without their noise (a known model: the
bound's premise); then, from ``clean``, ``no-tukey``, ``flat`` (the mask without the distance
fall-off), ``ivar`` (the mask over the expected Poisson variance, no fall-off), ``window`` (every
pixel of the window weighed 1), ``blur0.5`` (smoothing by 0.5 px, template and frame),
``tukey9`` (Tukey's constant 9); ``redraw``: the tracker's fit with a new noisy first frame (a new
template) at every draw, the template's noise counted (one frame against another: ``sqrt(2)`` times
the bound is the most to expect), and from it ``redraw-flat``, ``redraw-win``, ``redraw-b0.5``
(as above), ``redraw-lap2``, ``redraw-lap3`` (the blur term's Laplacian of the template smoothed
by 2 or 3 px more, not 1: ``TrackerParams.lap_blur``), ``redraw-nolap`` (no blur term); and, on a
frame blurred 2 px beyond the first (copy 2), ``copy2`` (the chequerboard, as the tracker fits
it) against ``copy2-full`` (every pixel). ``--only a,b`` runs those variants only.

``--sequences SEED [FRAMES]`` measures instead the tracker itself on the own plain set's sequences with the
shot noise alone (every frame's, the template's too; ``vision_ablation.py``'s ``only:noise+template-noise``):
each visible fix's error against the bound at its frame, rms per sequence.

Run: ``.venv/bin/python benchmarks/vision_efficiency.py [DRAWS] [--only a,b]`` (default 200 draws;
about 10 minutes for every variant under load); ``... --sequences SEED [FRAMES]`` (400 frames: about 5 minutes).
Not a test: a measurement (docs/vision-log.md, "The fit's efficiency").
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

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "benchmarks"), str(ROOT / "tests" / "support"), str(ROOT / "src")]
os.environ.setdefault("OMP_NUM_THREADS", "1")

import vision_ablation as va  # noqa: E402

from stickslip.sim.camera import SimCamSettings, SimScene  # noqa: E402
from stickslip.vision import refine as refine_mod  # noqa: E402
from stickslip.vision.refine import refine, steepest  # noqa: E402
from stickslip.vision.template import TrackerParams  # noqa: E402
from stickslip.vision.track import TipTracker  # noqa: E402

F = NDArray[np.float64]
SIZE = 128
H = 20
CASES = [  # look, apex width px, photons, blur px, taper deg, shaft direction deg
    ("optical", 4.0, 60.0, 1.0, 8.0, 30.0),
    ("optical", 16.0, 300.0, 1.0, 12.0, 200.0),
    ("optical", 10.0, 100.0, 2.0, 10.0, 120.0),
    ("sem", 5.0, 80.0, 1.0, 8.0, 300.0),
    ("sem", 16.0, 300.0, 1.0, 12.0, 75.0),
    ("sem", 10.0, 100.0, 2.0, 10.0, 160.0),
]
STEP = np.array([3.37, -2.61])


class Needle:
    """One needle's scene: flat ground, even light; noise-free frames and their noisy draws."""

    def __init__(self, look: str, width: float, photons: float, blur: float, taper: float, phi: float,
                 seed: int) -> None:
        self.scene = SimScene(SimCamSettings(look=look, width=SIZE, height=SIZE, photons=photons, seed=seed,
                                             tip_radius_m=0.25 * width * 1e-6, taper=math.radians(taper),
                                             pixel_size_m=0.5e-6))
        self.scene.substrate = np.full_like(self.scene.substrate, float(np.median(self.scene.substrate)))
        self.scene.illumination = np.full_like(self.scene.illumination, float(self.scene.illumination.mean()))
        self.scene.rng = va._NoNoise()  # type: ignore[assignment]
        self.look, self.photons, self.blur = look, photons, blur
        self.u = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi))])  # from the tip back
        self.rng = np.random.default_rng(seed)

    def clean(self, tip: F, blur: float | None = None, turn: float = 0.0) -> F:
        c, s = math.cos(turn), math.sin(turn)
        d = np.array([c * self.u[0] - s * self.u[1], s * self.u[0] + c * self.u[1]])
        return SimScene.render(self.scene, tip, d, self.blur if blur is None else blur)  # (not an ablated one's)

    def noisy(self, clean: F) -> F:
        counts = self.rng.poisson(np.clip(clean, 0.0, None) * self.photons).astype(float)
        if self.look == "sem":
            counts += self.rng.normal(0.0, 0.005 * self.photons, (clean.shape[0], 1))
        return np.asarray(np.clip(counts / self.photons, 0.0, 1.0), dtype=float)


def bound(nd: Needle, tip: F, blur: float, pick: NDArray[np.bool_] | None = None) -> F:
    """The Cramér-Rao covariance of the tip (x, y; px²) over the window around ``tip`` (``pick``: its pixels used)."""
    cx, cy = int(round(tip[0])), int(round(tip[1]))
    full = nd.clean(tip, blur)
    y0, y1 = max(cy - H, 0), min(cy + H + 1, full.shape[0])  # the window, within the frame
    x0, x1 = max(cx - H, 0), min(cx + H + 1, full.shape[1])
    sl = (slice(y0, y1), slice(x0, x1))
    mu = full[sl]
    h, dt, db = 0.1, 0.005, 0.1
    cols = [(nd.clean(tip + [h, 0], blur)[sl] - nd.clean(tip - [h, 0], blur)[sl]) / (2 * h),
            (nd.clean(tip + [0, h], blur)[sl] - nd.clean(tip - [0, h], blur)[sl]) / (2 * h),
            (nd.clean(tip, blur, dt)[sl] - nd.clean(tip, blur, -dt)[sl]) / (2 * dt),
            (nd.clean(tip, blur + db)[sl] - nd.clean(tip, blur - db)[sl]) / (2 * db)]
    yy, xx = np.mgrid[y0 - cy : y1 - cy, x0 - cx : x1 - cx] / (2 * H + 1)
    cols += [mu, mu * xx, mu * yy, np.ones_like(mu), xx, yy]
    J = np.stack([c.ravel() for c in cols], axis=1)
    var = np.clip(mu, 1e-6, None).ravel() / nd.photons
    use = np.ones(mu.size, bool) if pick is None else pick.ravel()
    jit2 = 0.005**2 if nd.look == "sem" else 0.0
    Fi = np.zeros((J.shape[1], J.shape[1]))
    n = x1 - x0
    for r in range(y1 - y0):  # a scan line's pixels share the SEM's jitter: one covariance block a line
        idx = np.arange(r * n, (r + 1) * n)[use[r * n : (r + 1) * n]]
        if idx.size == 0:
            continue
        S = np.diag(var[idx]) + jit2
        Jr = J[idx]
        Fi += Jr.T @ np.linalg.solve(S, Jr)
    Fi[2, 2] += 1.0 / 0.05**2  # the fit's prior on the turn (refine's theta_sd, rad)
    return np.asarray(np.linalg.inv(Fi)[:2, :2])


def _split(nd: Needle, cov: F) -> tuple[float, float]:
    """The sd along the axis and across it, px."""
    u = nd.u
    v = np.array([-u[1], u[0]])
    return float(math.sqrt(u @ cov @ u)), float(math.sqrt(v @ cov @ v))


def _tracker(first: F, tip: F, params: TrackerParams, clean_first: F | None) -> TipTracker:
    t = TipTracker(first, (float(tip[0]), float(tip[1])), params)
    if clean_first is not None:
        va._denoised(t, clean_first, (float(tip[0]), float(tip[1])))
    return t


def _weights(t: TipTracker, kind: str) -> F:
    """The sharp copy's weights for a variant."""
    w0 = t.template.level_weights[0]
    h = t.params.half_window
    ox, oy = np.mgrid[0 : 2 * h + 1, 0 : 2 * h + 1]
    radial = np.exp(-0.5 * ((oy - t.template.apex[0]) ** 2 + (ox - t.template.apex[1]) ** 2) / (h / 2.0) ** 2)
    flat = w0 / radial
    if kind == "flat":
        return np.asarray(flat)
    if kind == "ivar":
        tv = np.clip(t.template.bank[0], 0.02, None)
        return np.asarray(flat / tv * float(np.median(tv)))
    if kind == "window":
        return np.ones_like(w0)
    return np.asarray(w0)


def fits(nd: Needle, t: TipTracker, frame: F, tip: F, draws: int, level: int = 0, weights: str = "mask",
         thin: bool | None = None, robust: bool = True, lap: float = 1.0) -> tuple[F, F]:
    """The fit's errors (draws x 2, px) and reported covariances over ``draws`` noisy copies of ``frame``."""
    k, f, b = t._spec[level]
    w = t.template.level_weights[level] if weights == "mask" and level else _weights(t, weights)
    th = (math.hypot(t.params.template_blur, abs(b)) >= t.params.thin_blur) if thin is None else thin
    st = steepest(t.template.bank[k], t.template.apex, w, thin=th, lap_blur=lap if lap > 0 else 1.0)
    if lap <= 0:  # no blur term
        st = replace(st, lap=np.zeros_like(st.lap), sd_lap=np.zeros_like(st.sd_lap))
    err, covs = [], []
    for _ in range(draws):
        img = nd.noisy(frame)
        start = tip + nd.rng.normal(0.0, 0.2, 2)
        ref = refine(t._patch({}, img, float(start[0]), float(start[1]), f), st, (float(start[0]), float(start[1])),
                     0.0, robust=robust, correlation=t.params.sigma_factor)
        if ref.converged and math.hypot(ref.x - tip[0], ref.y - tip[1]) < 5.0:
            err.append((ref.x - tip[0], ref.y - tip[1]))
            covs.append(ref.cov * t.params.sigma_factor**2)
    return np.array(err).reshape(-1, 2), np.array(covs).reshape(-1, 2, 2)


def redrawn(nd: Needle, first_clean: F, tip0: F, frame: F, tip: F, draws: int, params: TrackerParams,
            weights: str = "mask", lap: float = 1.0) -> tuple[F, F]:
    """As :func:`fits`, each draw with a new noisy first frame too (a new template): the template's noise
    counted."""
    err, covs = [], []
    for _ in range(draws):
        t = _tracker(nd.noisy(first_clean), tip0, params, None)
        e, c = fits(nd, t, frame, tip, 1, weights=weights, lap=lap)
        err += list(e)
        covs += list(c)
    return np.array(err).reshape(-1, 2), np.array(covs).reshape(-1, 2, 2)


def _row(name: str, nd: Needle, err: F, covs: F, crb: tuple[float, float]) -> str:
    if len(err) < 10:
        return f"  {name:<12} {len(err)} fits converged"
    u = nd.u
    v = np.array([-u[1], u[0]])
    al, ac = err @ u, err @ v
    rep_al = float(np.sqrt(np.mean(np.einsum("i,nij,j->n", u, covs, u))))
    rep_ac = float(np.sqrt(np.mean(np.einsum("i,nij,j->n", v, covs, v))))
    sa, sc = float(al.std()), float(ac.std())
    ra, rc = (f"{r:.2f}" if math.isfinite(r) else "-" for r in (rep_al / sa, rep_ac / sc))
    return (f"  {name:<12} along sd {sa:.3f} bias {al.mean():+.3f} eff {crb[0] / sa:.2f} rep/sd {ra:>4} | "
            f"across sd {sc:.3f} bias {ac.mean():+.3f} eff {crb[1] / sc:.2f} rep/sd {rc:>4}  (n {len(err)})")


def case(i: int, spec: tuple[str, float, float, float, float, float], draws: int,
         only: list[str] | None = None) -> None:
    look, width, photons, blur, taper, phi = spec
    nd = Needle(look, width, photons, blur, taper, phi, 100 + i)
    tip0 = np.array([SIZE / 2 - 3.2, SIZE / 2 + 2.4])
    tip1 = tip0 + STEP
    first_clean = nd.clean(tip0)
    first = nd.noisy(first_clean)
    frame = nd.clean(tip1)
    p = TrackerParams()
    t_noisy = _tracker(first, tip0, p, None)
    t_clean = _tracker(first, tip0, p, first_clean)
    keep = t_clean.template.level_weights[0] > 1e-3 * float(t_clean.template.level_weights[0].max())
    crb = _split(nd, bound(nd, tip1, blur))
    crb_m = _split(nd, bound(nd, tip1, blur, keep))
    print(f"{look} {width:.0f} px, {photons:.0f} ph, blur {blur:.1f}: crb along {crb[0]:.3f} across {crb[1]:.3f}; "
          f"over the mask {crb_m[0]:.3f} / {crb_m[1]:.3f}", flush=True)
    runs: dict[str, Any] = {
        "main": lambda: fits(nd, t_noisy, frame, tip1, draws),
        "clean": lambda: fits(nd, t_clean, frame, tip1, draws),
        "no-tukey": lambda: fits(nd, t_clean, frame, tip1, draws, robust=False),
        "flat": lambda: fits(nd, t_clean, frame, tip1, draws, weights="flat"),
        "ivar": lambda: fits(nd, t_clean, frame, tip1, draws, weights="ivar"),
        "window": lambda: fits(nd, t_clean, frame, tip1, draws, weights="window"),
        "blur0.5": lambda: fits(nd, _tracker(first, tip0, replace(p, template_blur=0.5), first_clean), frame, tip1,
                                draws),
        "redraw": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, p),
        "redraw-flat": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, p, "flat"),
        "redraw-win": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, p, "window"),
        "redraw-lap2": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, p, lap=2.0),
        "redraw-lap3": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, p, lap=3.0),
        "redraw-nolap": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, p, lap=0.0),
        "redraw-b0.5": lambda: redrawn(nd, first_clean, tip0, frame, tip1, draws, replace(p, template_blur=0.5)),
        "tukey9": lambda: _tukey(9.0, lambda: fits(nd, t_clean, frame, tip1, draws)),
    }
    for name, run in runs.items():
        if only is None or name in only:
            err, covs = run()
            print(_row(name, nd, err, covs, crb), flush=True)
    if only is None or "copy2" in only:
        b2 = math.hypot(blur, 2.0)
        frame2 = nd.clean(tip1, b2)
        crb2 = _split(nd, bound(nd, tip1, b2))
        print(f"  frame blurred to {b2:.2f} px (copy 2): crb along {crb2[0]:.3f} across {crb2[1]:.3f}")
        for name, thin in (("copy2", None), ("copy2-full", False)):
            err, covs = fits(nd, t_clean, frame2, tip1, draws, level=2, thin=thin)
            print(_row(name, nd, err, covs, crb2), flush=True)


def _tukey(c: float, run: Any) -> Any:
    kept = refine_mod.TUKEY
    refine_mod.TUKEY = c
    try:
        return run()
    finally:
        refine_mod.TUKEY = kept


def _bound_at(scene: SimScene, args: tuple[Any, ...], photons: float, look: str) -> F:
    """:func:`bound` for a frame ``scene`` rendered with ``args`` (its tip, direction and blur)."""
    tip, direction, sigma = np.asarray(args[0], dtype=float), np.asarray(args[1], dtype=float), float(args[2])
    nd = Needle.__new__(Needle)
    nd.scene, nd.look, nd.photons, nd.blur = scene, look, photons, sigma
    nd.u = direction / float(np.hypot(*direction))
    kept = scene.rng
    scene.rng = va._NoNoise()  # type: ignore[assignment]
    try:
        return bound(nd, tip, max(sigma, 0.45))
    finally:
        scene.rng = kept


def sequences(seed: int, n_frames: int) -> None:
    """The own plain set's noise-only sequences (``vision_ablation``'s ``only:noise+template-noise``: the shot
    noise in every frame, the template's too): each visible fix's error against the bound at its frame, per
    sequence (rms along | across, px) and the efficiency (rms bound / rms error; a one-frame template's bound
    is sqrt(2) times this one's)."""
    seen: list[tuple[Any, tuple[Any, ...]]] = []
    plain = SimScene.render

    def recording(self: SimScene, *args: Any) -> F:
        seen.append((self, args))
        return plain(self, *args)

    scene_cls = va.ablated(frozenset(va.FACTORS) - {"noise", "template-noise"})
    setattr(va.vision_own, "SimScene", scene_cls)  # noqa: B010
    SimScene.render = recording  # type: ignore[method-assign]
    try:
        seqs = va.vision_own.own_benchmark(n_frames, 40, seed=seed, size=256)
    finally:
        SimScene.render = plain  # type: ignore[method-assign]
        setattr(va.vision_own, "SimScene", SimScene)  # noqa: B010
    print(f"own plain set, seed {seed}, noise only: per sequence, rms along | across px (error; bound), efficiency")
    all_e, all_b = [], []
    for i, seq in enumerate(seqs):
        calls = seen[i * 40 : (i + 1) * 40]
        images = [f.image for f in seq.frames]
        try:
            tr = TipTracker(images[0], seq.frames[0].tip)
        except ValueError:
            continue
        e, b = [], []
        for f, img, (scene, args) in zip(seq.frames[1:], images[1:], calls[1:], strict=True):
            r = tr.update(img)
            if f.kind != "visible" or not hasattr(r, "x"):
                continue
            u = np.asarray(args[1], dtype=float)
            u = u / float(np.hypot(*u))
            v = np.array([-u[1], u[0]])
            d = np.array([r.x - f.tip[0], r.y - f.tip[1]])
            cov = _bound_at(scene, args, seq.photons, seq.look)
            e.append((d @ u, d @ v))
            b.append((u @ cov @ u, v @ cov @ v))
        if len(e) < 3:
            continue
        ea, ba = np.array(e), np.array(b)
        rms_e, rms_b = np.sqrt(np.mean(ea**2, axis=0)), np.sqrt(np.mean(ba, axis=0))
        all_e += e
        all_b += b
        print(f"  seq {i} {seq.look[:3]} {seq.width_px:4.1f} px {seq.photons:3.0f} ph {len(e):>3} fixes: error "
              f"{rms_e[0]:.3f} | {rms_e[1]:.3f}, bound {rms_b[0]:.3f} | {rms_b[1]:.3f}, efficiency "
              f"{rms_b[0] / rms_e[0]:.2f} | {rms_b[1] / rms_e[1]:.2f}", flush=True)
    ea, ba = np.array(all_e), np.array(all_b)
    rms_e, rms_b = np.sqrt(np.mean(ea**2, axis=0)), np.sqrt(np.mean(ba, axis=0))
    print(f"  all {len(ea)} fixes: error {rms_e[0]:.3f} | {rms_e[1]:.3f}, bound {rms_b[0]:.3f} | {rms_b[1]:.3f}, "
          f"efficiency {rms_b[0] / rms_e[0]:.2f} | {rms_b[1] / rms_e[1]:.2f}")


def main(argv: list[str]) -> None:
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(argv, ["--sequences", "--only"], __doc__)
    if "--sequences" in argv:
        k = argv.index("--sequences")
        sequences(int(argv[k + 1]), int(argv[k + 2]) if len(argv) > k + 2 else 400)
        return
    only = None
    if "--only" in argv:
        k = argv.index("--only")
        only = argv[k + 1].split(",")
        argv = argv[:k] + argv[k + 2:]
    draws = int(argv[0]) if argv else 200
    for i, spec in enumerate(CASES):
        case(i, spec, draws, only)


if __name__ == "__main__":
    main(sys.argv[1:])
