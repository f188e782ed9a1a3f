"""Seeing the tip: tracking on frames the tracker was not designed on, and step sizes measured by camera.

1. **Tracking** (issue 30): 500 frames of the second renderer (``tests/support/vision_peer.py``:
   hyperboloid needles, pillbox defocus, side-detector SEM contrast, Fresnel fringes,
   real micrographs from scikit-image as backgrounds), 512 x 512, ten sequences of 50
   frames with tip widths 3..20 px, blur up to sigma 3 px, shot noise down to 40 photons
   a pixel, turns of a few degrees, image drift, and frames with the tip out of the
   field, occluded or far out of focus. Printed beside the issue's numbers: the median
   and 95th percentile error on visible frames, the largest error of any fix, the share
   of visible tips refused, the tips out of the field fixed, and frames per second of
   the tracker alone on one core (the rendering not counted), by the wall clock and by
   the process's CPU time (on a shared machine the CPU time is the tracker's own cost).
2. **Camera calibration**: ``stickslip.procedures.camera.calibrate_camera`` on
   ``sim://`` with ``simcam://`` at 0.5 um a pixel, joints 3 and 1 at the outstretched
   pose, at most 200 steps each way, five simulated arms in each look: the step size
   measured against the realized mean step (the simulator's true positions before and
   after every burst).

Run: ``.venv/bin/python benchmarks/bench_vision.py [FRAMES] [--tracking-only]`` (default 500;
a few minutes; ``--tracking-only`` skips the calibration).

``--lobed`` measures instead the tracker on the OWN renderer's frames in its lobed mode
(``tests/support/vision_own.py``'s ``lobed_benchmark``, 256 x 256, sequences of 40: lobed
grains of 2 to 4 discs, 1 to 2.5 times the tip's width, darker or lighter than the
needle, over the tip; tips 4 to 12 px inside the field's edge): the fixes more than 3 px
off and the worst, and the verdicts by what the frame is (``FRAMES`` default 400), for tips
3 to 20 px in both looks, then for wide tips (14 to 18 px) in bright field.

``--flake`` does the same in the own renderer's flake mode (``flake_benchmark``: a flat,
nearly opaque chip with rounded corners stuck on the tip for 1 to 4 frames, reaching 0.9
to 1.5 tip widths from its middle, sharper than the needle; ``FRAMES`` default 200).

``--round`` does the same in the own renderer's round mode (``round_benchmark``: a blunt,
paraboloid-ended needle; a round, nearly opaque bead 0.6 to 1.5 tip widths in radius stuck
on its end for 1 to 4 frames, sharper than the needle; tips held 8 to 24 px inside the
edge their shaft leaves by, with a bead or without; ``FRAMES`` default 200).

``--droplet`` does the same in the own renderer's droplet mode (``droplet_benchmark``: a
transparent droplet clinging to the tip refracts it, bright field only; ``FRAMES`` default 200;
the "wide" run is its seed 1, tips 14 to 18 px).

``--micrograph [SEQUENCES]`` does the same over real micrographs (``micrograph_benchmark``: the own renderer's
bright-field frames with scikit-image's ``microaneurysms.png`` zoomed 4 times or ``retina.jpg``'s green channel
as the substrate, files the second renderer does not use; tips 10 to 18 px, 50 to 120 photons, events at 0.15 a
frame; seeds 1 to 3 of each ground, ``SEQUENCES`` of 40 frames each, default 40); without scikit-image (the dev
extra) it says so and measures nothing.

``--seed N`` takes the second renderer's draw ``N`` (``peer_benchmark(seed=N)``: other looks, backgrounds,
paths and events; default 0, the draw every number above was measured on), for the tracking, ``--refusals``
and ``--scenes`` (the third generator's draw ``N`` only, tips 6 to 22 px).

``--defocus disc`` draws the own renderer's modes (and ``--micrograph``, ``--plain``) with geometric optics'
blur circle of the same variance instead of the Gaussian defocus (``SimCamSettings(defocus="disc")``).

``--params NAME=VALUE,...`` tracks every mode with those of the tracker's constants changed
(``TrackerParams``' fields, e.g. ``--params mismatch_floor=0.03``): a change measured side by side.

``--tracking-only --refusals`` sorts instead the second renderer's refused visible tips (the
same frames as 1.): one row each (the sequence's look, background, tip width and photons,
the frame's blur and room to the field's edge, the verdict before it), the rule that
refused it (read from the refusal's detail: which check of ``track.py`` said it) and how
far the fit it refused lay from the truth; the fit near the last fix, replayed from the
tracker's state before the frame (``TipTracker``'s own search and judgement, the same
calls ``update`` makes; nothing in the tracker changed), and the nearest of the whole
frame's candidates. Then the counts by rule (fits within 1 px, 1 to 3 px, more than
3 px) and by sequence; every fix more than 2 px off with what took it (near the last fix or the
whole frame's search, the blur copy, the signals the rules read: ``_judge`` wrapped on the
instance, every decision unchanged); and the draw's numbers (visible, refused, median, 95th
percentile, largest, fixes more than 3 px off, tips out of the field refused) with each
sequence's conditions.

``--vouch-signals [FRAMES [OWN]]`` reads, on every candidate the "nothing vouches" rule refused
(fewer than three width stations in the frame behind it; near the last fix or in the whole
frame), the other signals the tracker has or could have cheaply: the distance from where the
last two fixes' motion puts the tip and from the last fix, the turn against the last fix, the
correlation and mismatch ratio, sigma, the template's share inside the frame, the edges'
contrast and shape behind the tip. Candidates of the second renderer (``FRAMES``, default 500)
and of the own round mode (both sets) and lobed mode (wide set) (``OWN`` frames each, default
200) are grouped by renderer and by their distance from the truth (good: 3 px or less); each
signal's ranges by group, whether one threshold separates the wrong from the good, and for
each pair of signals the good candidates inside the wrong ones' box. The tracker is not
changed: its ``_judge`` is wrapped on the instance to record what it refused.

``--error-split [FRAMES [OWN]]`` splits each visible tip's error into its component along the
needle's axis (positive: behind the tip, up the shaft; the axis is the template's shaft
direction turned by the fix's angle) and across it, and prints each one's mean (the bias)
and spread, by sequence (look, tip width, photons, blur range) of the second renderer
(``FRAMES``, default 500) and of the own renderer's plain, lobed and round sets (``OWN``
frames each, default 200), then by the frame's blur against the first frame's (signed: a
negative one is sharper), by how far the blur copy the fix was fitted with lies from it, and
by the needle's turn since the first frame.

``--border-signals [OWN]`` reads instead, on the own round mode's candidates "nothing vouches" refused
(seeds 0 and 2, 1 and 3 wide) and the lobed mode's wide set (``OWN`` frames each, default 400), the
outline behind the fit up to the field's border: across the axis every 2 px, whether the axis is needle
there, how long a stretch is not, the largest narrowing going back, and the width against the first
frame's as far behind its tip (good against wrong, near the last fix and found again).

``--scenes`` does the same on the third generator's frames (``tests/support/occlusion_scenes.py``:
power-law and truncated needles in transmitted light, a Moffat or ring point spread, speckle;
fibres, refracting droplets, drifting particles and shadows over the tip; 256 x 256, sequences of
30; ``FRAMES`` default 300, seeds 0 and 1), then for blunt tips 12 to 22 px wide: the fixes more
than 3 px off, and the verdicts by what the frame is (occluded or visible, and the cause).

``--plain`` does the same on the own renderer's plain frames (``own_benchmark`` seeds 0, 1
and 2, tips 3 to 20 px, both looks; ``FRAMES`` default 400 each): what a change to the
tracker must not make worse.
"""

from __future__ import annotations

import os

# "one core": the linear algebra library's threads would otherwise share the tracker's small products over every core
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402
import sys  # noqa: E402
import textwrap  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterable, Iterator, Sequence  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "support"))

from occlusion_scenes import scene_benchmark  # noqa: E402
from vision_own import (  # noqa: E402
    OwnFrame,
    droplet_benchmark,
    flake_benchmark,
    lobed_benchmark,
    micrograph_benchmark,
    own_benchmark,
    round_benchmark,
)
from vision_peer import peer_benchmark  # noqa: E402

from stickslip.devices.base import DeviceInfo  # noqa: E402
from stickslip.procedures.camera import calibrate_camera  # noqa: E402
from stickslip.sim.arm import SimulatedMM3A  # noqa: E402
from stickslip.sim.camera import SimCamera, SimCamSettings  # noqa: E402
from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.template import TemplateError, TrackerParams  # noqa: E402
from stickslip.vision.track import Fix, Lost, TipTracker, _edge_refusal, _padded  # noqa: E402

PARAMS = TrackerParams()
"""The tracker's constants in every mode (``--params NAME=VALUE,...`` changes some: a change measured side by side)."""

DEFOCUS = "gaussian"
"""The own renderer's defocus in its modes (``--defocus disc``: geometric optics' blur circle of the same variance)."""


def _set_params(spec: str) -> None:
    """``NAME=VALUE,...`` into :data:`PARAMS` (each value of its field's type)."""
    global PARAMS
    changes: dict[str, Any] = {}
    for item in spec.split(","):
        name, value = item.split("=")
        kind = type(getattr(PARAMS, name))
        changes[name] = value.lower() in ("1", "true", "yes") if kind is bool else kind(value)
    PARAMS = replace(PARAMS, **changes)


def tracking(n_frames: int, seed: int = 0) -> dict[str, float]:
    seqs = peer_benchmark(n_frames, 50, seed=seed, size=512)
    errors, worst, refused, visible, out_fixed, out_total, seconds, cpu, tracked = [], 0.0, 0, 0, 0, 0, 0.0, 0.0, 0
    kinds: dict[str, int] = {}
    verdicts: dict[tuple[str, str], int] = {}
    print(f"{'sequence':>8} {'look':>11} {'background':>10} {'tip px':>6} {'photons':>7} {'median':>7} {'p95':>6} "
          f"{'max':>6} {'refused':>7} {'worst fix':>9}")
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        learnt = _learnt(i, seq, images[0])
        if learnt is None:
            continue
        tracker = learnt
        errs, ref, seq_worst = [], 0, 0.0
        for f, img in zip(seq.frames[1:], images[1:], strict=True):
            t, c = time.perf_counter(), time.process_time()
            r = tracker.update(img)
            seconds += time.perf_counter() - t
            cpu += time.process_time() - c
            tracked += 1
            kinds[f.kind] = kinds.get(f.kind, 0) + 1
            visible += f.kind == "visible"
            out_total += f.kind == "out"
            verdict = "fix" if isinstance(r, Fix) else r.reason
            verdicts[(f.kind, verdict)] = verdicts.get((f.kind, verdict), 0) + 1
            if isinstance(r, Fix):
                e = math.hypot(r.x - f.tip[0], r.y - f.tip[1])
                worst = max(worst, e)
                seq_worst = max(seq_worst, e)
                out_fixed += f.kind == "out"
                if f.kind == "visible":
                    errs.append(e)
            elif f.kind == "visible":
                ref += 1
        refused += ref
        errors += errs
        e = np.array(errs) if errs else np.array([math.nan])
        print(f"{i:>8} {seq.look:>11} {seq.background:>10} {seq.width_px:>6.1f} {seq.photons:>7.0f} "
              f"{np.median(e):>7.2f} {np.percentile(e, 95):>6.2f} {np.max(e):>6.2f} {ref:>7} {seq_worst:>9.2f}")
    e = np.array(errors)
    out = {
        "median": float(np.median(e)), "p95": float(np.percentile(e, 95)), "worst": worst,
        "refused": refused / max(visible, 1), "out_fixed": out_fixed, "out_total": out_total,
        "fps": tracked / seconds, "fps_cpu": tracked / cpu, "frames": tracked + len(seqs), "visible": visible,
    }
    print(f"frames: {out['frames']} ({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))}; "
          f"{len(seqs)} first frames give the tip)")
    print("verdicts by kind: " + "; ".join(f"{k}: {v} {n}" for (k, v), n in sorted(verdicts.items())))
    rows = [
        ("median error, visible (px)", out["median"], 0.3, "<="),
        ("95th percentile, visible (px)", out["p95"], 1.0, "<="),
        ("largest error of any fix (px)", out["worst"], 3.0, "<="),
        ("visible tips refused (%)", 100 * out["refused"], 2.0, "<="),
        ("tips out of the field fixed", out["out_fixed"], 0.0, "<="),
        ("frames per second, one core (wall)", out["fps"], 200.0, ">="),
        ("frames per second, one core (CPU)", out["fps_cpu"], 200.0, ">="),
    ]
    print(f"{'':36} {'measured':>9} {'issue':>7} {'ratio':>7}  met")
    for name, v, target, op in rows:
        ratio = v / target if target else (0.0 if v == 0 else math.inf)
        met = v <= target if op == "<=" else v >= target
        print(f"{name:36} {v:>9.3f} {op}{target:>6g} {ratio:>7.2f}  {'yes' if met else 'NO'}")
    return out


def learnt_sequences(seqs: Iterable[Any], params: TrackerParams) -> Iterator[tuple[int, Any, TipTracker, list[Any]]]:
    """Each sequence of ``seqs`` whose first frame teaches a tracker (``params``): its index, the sequence, the tracker
    and its frames read as images. One whose first frame does not is left out without a word (no frame of it in any
    count; :func:`_learnt` prints why)."""
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            tracker = TipTracker(images[0], seq.frames[0].tip, params)
        except TemplateError:
            continue
        yield i, seq, tracker, images


def _learnt(i: int, seq: Any, first: np.ndarray) -> TipTracker | None:
    """The tracker learnt from ``seq``'s first frame, or ``None`` with the refusal printed (the sequence is then
    left out of every count: no frame of it is tracked)."""
    try:
        return TipTracker(first, seq.frames[0].tip, PARAMS)
    except TemplateError as exc:
        n_vis = sum(f.kind == "visible" for f in seq.frames[1:])
        print(f"sequence {i} ({seq.look}, {seq.background}, tip {seq.width_px:.1f} px, {seq.photons:.0f} photons, "
              f"first frame's blur {seq.frames[0].blur:.1f} px; {n_vis} visible tips) not learnt: {exc}")
        return None


# the refusal's detail -> (the check that said it, its reason); the first match wins (track.py's strings)
_RULES = (
    ("the tip would be", "edge margin"),
    ("of the tip's window is outside", "coverage"),
    ("of the tip's template disagrees", "outliers"),
    ("of the ground in front of the tip", "front share"),
    ("that copy matches as well", "top copy read"),
    ("or more against the first frame", "top blur copy"),
    ("worse than this sequence's fixes", "mismatch"),
    ("correlation ", "min score"),
    ("the match needs a turn", "turn"),
    ("did not settle", "not settled"),
    ("did not converge", "not converged"),
    ("position undetermined", "sigma"),
    ("the focus would have changed", "focus step"),
    ("found again only blurred", "found blurred"),
    ("shaft", "shaft back"),
    ("taper puts its end", "taper"),
    ("edges behind the tip have", "edge contrast"),
    ("edges behind the tip are not where", "edge shape"),
    ("edges fade right behind", "edges near"),
    ("nothing vouches", "nothing vouches"),
    ("not as wide as the first frame", "width"),
    ("registered width", "width narrow"),
    ("wider than the first frame's by", "width near wide"),
    ("not found near the last fix", "not found"),
)


def _rule(res: Lost) -> str:
    """The check of ``track.py`` that gave refusal ``res``, by a short name."""
    for key, name in _RULES:
        if key in res.detail:
            return name
    return f"? {res.detail[:40]}"


def _state(t: TipTracker) -> dict[str, object]:
    """What ``TipTracker.update`` changes between frames (the caches aside)."""
    return {k: (list(v) if isinstance(v, list) else v) for k, v in vars(t).items()
            if k in ("_last", "_theta", "_level", "_fresh", "_since", "_mismatch")}


def _replay(t: TipTracker, image: np.ndarray, tip: tuple[float, float]
            ) -> tuple[Lost | None, float, float, str, str]:
    """``update``'s search and judgement on ``image`` from ``t``'s state, nothing accepted.

    Returns the fit near the last fix's refusal (``None``: no fit there), its distance from
    ``tip`` (px, NaN without one), the whole frame's candidate nearest ``tip``: its
    distance (px, NaN without one) and its verdict, and the rule that refused the frame's
    best-correlating candidate (the one ``update`` names; "not found" without one).
    """
    def dist(c: object) -> float:
        r = c.ref  # type: ignore[attr-defined]
        return math.hypot(r.x - tip[0], r.y - tip[1]) if math.isfinite(r.x) and math.isfinite(r.y) else math.inf

    near, e_near = None, math.nan
    cand = t._local(image)
    if cand is not None:
        res, cand = t._judge(cand, image)
        e_near = dist(cand)
        near = res if isinstance(res, Lost) else None
        # as update: a fit refused only because nothing vouches for it goes on to the whole frame
        if isinstance(res, Lost) and res.reason in ("lost", "out of focus") and cand.edges is not None and (
                not getattr(cand, "unvouched", False)) and _edge_refusal(cand.edges, t.params, cand.shaft) is None:
            return near, e_near, math.nan, "not searched", "not searched"
    e_glob, v_glob = math.nan, "none"
    best: tuple[float, str] = (-math.inf, "not found")
    for g in t._global(image):
        if g is None:
            continue
        res, g = t._judge(g, image, reacquire=True)
        e = dist(g)
        if not e >= e_glob:
            e_glob, v_glob = e, ("fix" if isinstance(res, Fix) else _rule(res))
        if isinstance(res, Lost) and g.ref.score > best[0]:
            best = (g.ref.score, _rule(res))
    return near, e_near, e_glob, v_glob, best[1]


def _in_reach(t: TipTracker, tip: tuple[float, float], w: int, h: int) -> bool:
    """Whether ``TipTracker._global``'s down-sampled correlation can put the template's apex at ``tip``: the
    nearest coarse offset lies in its padded frame (the template hanging over the border until its tip lies on
    the edge) with at least ``min_coverage`` of the template's weight inside."""
    f = t.params.coarse_factor
    small, inside, pad = _padded(np.zeros((h, w)), f, t.template.half, {})
    ax, ay = t.template.apex
    j, i = int(round((tip[0] - ax) / f)) + pad, int(round((tip[1] - ay) / f)) + pad
    n = t._coarse[0].shape[0]
    if not (0 <= i <= small.shape[0] - n and 0 <= j <= small.shape[1] - n):
        return False
    cover = float((t._coarse_w * inside[i : i + n, j : j + n]).sum() / t._coarse_w.sum())
    return cover >= t.params.min_coverage


def refusals(n_frames: int, seed: int = 0) -> int:
    """Sort the second renderer's refused visible tips by the rule that refused them; the rows."""
    seqs = peer_benchmark(n_frames, 50, seed=seed, size=512)
    rows: list[tuple[int, int, float, float, str, str, float, float, str, float, bool]] = []
    reasons: dict[str, str] = {}
    differ = visible = 0
    taken: list[tuple[int, int, str, float, dict[str, Any] | None]] = []  # every fix: sequence, frame, kind, error
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        tracker = _learnt(i, seq, images[0])
        if tracker is None:
            continue
        judged = _watch(tracker)
        fixes: list[tuple[int, float, float]] = [(0, *seq.frames[0].tip)]
        before = "fix"
        for k, (f, img) in enumerate(zip(seq.frames[1:], images[1:], strict=True), start=1):
            pre = _state(tracker)
            judged.clear()
            r = tracker.update(img)
            if isinstance(r, Fix):
                e = math.hypot(r.x - f.tip[0], r.y - f.tip[1])
                taken.append((i, k, f.kind, e, _taken_by(tracker, pre, r, judged, fixes, k, f, img) if e > 2.0
                              else None))
                fixes.append((k, r.x, r.y))
            visible += f.kind == "visible"
            if isinstance(r, Lost) and f.kind == "visible":
                post = _state(tracker)
                vars(tracker).update(pre)
                near, e_near, e_glob, v_glob, v_best = _replay(tracker, img, f.tip)
                vars(tracker).update(post)
                differ += (_rule(near) if near else v_best) != _rule(r)
                reasons[_rule(r)] = r.reason
                h, w = img.shape
                room = min(f.tip[0], f.tip[1], w - 1 - f.tip[0], h - 1 - f.tip[1])
                last = pre["_last"]
                gone = math.hypot(f.tip[0] - last[0], f.tip[1] - last[1])  # type: ignore[index]
                rows.append((i, k, f.blur, room, before, _rule(r), e_near, e_glob, v_glob, gone,
                             _in_reach(tracker, f.tip, w, h)))
            before = "fix" if isinstance(r, Fix) else "refused" if f.kind == "visible" else f.kind[:7]
    print("columns: sequence, frame, blur (px), room to the field's edge (px), the frame\n"
          "before (fix, refused, or what it was), the rule that refused, the truth's\n"
          "distance from the last fix (px), whether the whole frame's search can put the\n"
          "template there, the distance from the truth (px) of the refused fit near the\n"
          "last fix and of the whole frame's nearest candidate, that candidate's verdict")
    print(f"{'seq':>3} {'fr':>2} {'blur':>4} {'room':>4} {'before':>7} {'rule':<15} {'last':>5} {'rch':>3} "
          f"{'near':>4} {'frame':>5} nearest's")
    for i, k, bl, room, bef, rule, en, eg, vg, gone, reach in rows:
        print(f"{i:>3} {k:>2} {bl:>4.1f} {room:>4.0f} {bef:>7} {rule:<15} {gone:>5.1f} "
              f"{'yes' if reach else 'no':>3} {en:>4.1f} {eg:>5.1f} {vg}")
    print(f"{len(rows)} of {visible} visible tips refused; the replay refuses by another rule in {differ}")
    _off_fixes(taken)

    def bands(es: list[float]) -> str:
        a = np.array([e for e in es if math.isfinite(e)])
        if a.size == 0:
            return f"{'':>3} {'':>3} {'':>3} {'':>4} {'':>4}"
        return (f"{int(np.sum(a <= 1)):>3} {int(np.sum((a > 1) & (a <= 3))):>3} {int(np.sum(a > 3)):>3} "
                f"{np.median(a):>4.1f} {a.max():>4.1f}")

    print("\nby rule: the distance from the truth (px) of the refused fit near the last fix\n"
          "(near) and of the whole frame's nearest candidate (frame): how many within 1 px,\n"
          "1 to 3 px and more than 3 px, their median and largest")
    print(f"{'':<15} {'':>3} {'':>3} {'':>3}  {'near':<20}  frame")
    print(f"{'rule':<15} {'n':>3} {'sem':>3} {'bf':>3}  {'<=1':>3} {'1-3':>3} {'>3':>3} {'med':>4} {'max':>4}  "
          f"{'<=1':>3} {'1-3':>3} {'>3':>3} {'med':>4} {'max':>4}")
    look = {i: s.look for i, s in enumerate(seqs)}
    for rule in [*sorted(reasons, key=lambda u: -sum(r[5] == u for r in rows)), "all"]:
        mine = [r for r in rows if rule in ("all", r[5])]
        print(f"{rule:<15} {len(mine):>3} {sum(look[r[0]] == 'sem' for r in mine):>3} "
              f"{sum(look[r[0]] == 'brightfield' for r in mine):>3}  {bands([r[6] for r in mine])}  "
              f"{bands([r[7] for r in mine])}")
    print(textwrap.fill("reasons: " + ", ".join(f"{u}: {v}" for u, v in sorted(reasons.items())), 80))
    print("\nby sequence: look, background, tip width, photons a pixel; refused visible tips")
    for i, seq in enumerate(seqs):
        mine = [r for r in rows if r[0] == i]
        n_vis = sum(f.kind == "visible" for f in seq.frames[1:])
        tally: dict[str, int] = {}
        for r in mine:
            tally[r[5]] = tally.get(r[5], 0) + 1
        print(textwrap.fill(
            f"{i:>2} {'bf' if seq.look == 'brightfield' else seq.look:>3} {seq.background:>6} {seq.width_px:>4.1f} "
            f"{seq.photons:>3.0f}: {len(mine):>2} of {n_vis:>2}" + ("; " if tally else "")
            + ", ".join(f"{u} {n}" for u, n in sorted(tally.items(), key=lambda x: -x[1])),
            80, subsequent_indent=" " * 4))
    _draw_summary(seqs, taken, rows)
    return len(rows)


def _watch(tracker: TipTracker) -> list[tuple[bool, object, Any]]:
    """Wrap ``tracker``'s ``_judge`` on the instance: each judgement (whole frame's or not, result, candidate) is
    appended to the list returned; every decision unchanged."""
    judged: list[tuple[bool, object, Any]] = []
    judge = tracker._judge

    def watched(cand: Any, image: np.ndarray, reacquire: bool = False) -> Any:
        res, cand = judge(cand, image, reacquire)
        judged.append((reacquire, res, cand))
        return res, cand

    tracker._judge = watched  # type: ignore[method-assign]
    return judged


def _taken_by(t: TipTracker, pre: dict[str, object], fix: Fix, judged: list[tuple[bool, object, Any]],
              fixes: list[tuple[int, float, float]], k: int, f: Any, image: np.ndarray) -> dict[str, Any]:
    """What took ``fix`` (a fix more than 2 px off): the path (near the last fix, or the whole frame's search),
    the blur copy, and the signals the rules read, with the tracker's state before the frame (``pre``)."""
    # the fix the rules took (with TrackerParams.needle_judge it is then placed at the needle's tip: another object,
    # its score, sigma, blur and turn the same)
    reacquire, cand = next((ra, c) for ra, res, c in judged if res is fix or isinstance(res, Fix) and (
        res.score, res.sigma, res.blur, res.angle) == (fix.score, fix.sigma, fix.blur, fix.angle))
    post = _state(t)
    vars(t).update(pre)
    _, sig = _signals(t, cand, fixes, k, f.tip)
    vars(t).update(post)
    h, w = image.shape
    sh, wd = cand.shaft, cand.width
    return {"path": "frame" if reacquire else "near", "blur": getattr(f, "blur", math.nan), "fit blur": fix.blur,
            "copy": t._spec[cand.level][2],
            "room": min(f.tip[0], f.tip[1], w - 1 - f.tip[0], h - 1 - f.tip[1]), **sig,
            "back": sh.back if sh else math.nan, "shaft shape": sh.shape if sh else math.nan,
            "along": sh.along if sh else math.nan, "stations": wd.n if wd else -1,
            "disagree": wd.disagree if wd else -1,
            "along err": _along(t, fix, f.tip)}


def _along(t: TipTracker, fix: Fix, tip: tuple[float, float]) -> float:
    """The fix's error along the needle's axis (px; positive: behind the tip, up the shaft)."""
    a, _ = _split(fix, tip, t.template.shaft)
    return a


def _off_fixes(taken: list[tuple[int, int, str, float, dict[str, Any] | None]]) -> None:
    """Every fix more than 2 px from the truth, with what took it (:func:`_taken_by`)."""
    off = [r for r in taken if r[3] > 2.0]
    print(f"\nfixes more than 2 px off: {len(off)} ({sum(r[3] > 3.0 for r in off)} more than 3 px)")
    for i, k, kind, e, d in sorted(off, key=lambda r: -r[3]):
        print(textwrap.fill(f"  seq {i} frame {k} ({kind}) {e:.2f} px: " + _details(d or {}), 100,
                            subsequent_indent=" " * 6))


def _details(d: dict[str, Any]) -> str:
    """:func:`_taken_by`'s dictionary on one line."""
    return ", ".join(f"{key} {v}" if isinstance(v, str) else f"{key} {v:.3g}" for key, v in d.items())


def _draw_summary(seqs: Sequence[Any], taken: list[tuple[int, int, str, float, dict[str, Any] | None]],
                  rows: Sequence[tuple[Any, ...]]) -> None:
    """The draw's numbers: visible tips, refused, the visible fixes' median, 95th percentile, the largest error of
    any fix, fixes more than 3 px off, tips out of the field refused; by sequence its conditions."""
    vis = np.array([e for _, _, kind, e, _ in taken if kind == "visible"])
    ids = {r[0] for r in taken} | {r[0] for r in rows}
    learnt = [s for i, s in enumerate(seqs) if i in ids]
    n_vis = sum(f.kind == "visible" for s in learnt for f in s.frames[1:])
    n_out = sum(f.kind == "out" for s in learnt for f in s.frames[1:])
    out_fixed = sum(kind == "out" for _, _, kind, _, _ in taken)
    worst = max((e for *_, e, _ in taken), default=math.nan)
    print(f"\ndraw: visible {n_vis}, refused {len(rows)} ({100 * len(rows) / max(n_vis, 1):.1f} %), median "
          f"{np.median(vis):.3f} px, p95 {np.percentile(vis, 95):.3f}, largest {worst:.2f}, fixes > 3 px "
          f"{sum(e > 3.0 for *_, e, _ in taken)}, > 2 px {sum(e > 2.0 for *_, e, _ in taken)}, out of the field "
          f"refused {n_out - out_fixed} of {n_out}; fixes by kind: " + ", ".join(
              f"{u} {sum(kind == u for _, _, kind, _, _ in taken)}" for u in ("visible", "occluded", "defocused")))
    print("by sequence: look, background, tip px, photons, blur range of visible frames (px), refused, median, "
          "largest fix")
    for i, seq in enumerate(seqs):
        bl = [f.blur for f in seq.frames[1:] if f.kind == "visible"]
        if i not in ids:
            print(f"{i:>2} {seq.look:>11} {seq.background:>7} {seq.width_px:>5.1f} {seq.photons:>4.0f} "
                  f"{min(bl):>4.1f}-{max(bl):<4.1f} not learnt ({len(bl)} visible tips)")
            continue
        e = [x for j, _, _, x, _ in taken if j == i]
        ev = [x for j, _, kind, x, _ in taken if j == i and kind == "visible"]
        ref = sum(r[0] == i for r in rows)
        print(f"{i:>2} {seq.look:>11} {seq.background:>7} {seq.width_px:>5.1f} {seq.photons:>4.0f} "
              f"{min(bl):>4.1f}-{max(bl):<4.1f} {ref:>2}/{len(bl):<2} ({100 * ref / max(len(bl), 1):>4.1f} %) "
              f"{np.median(ev) if ev else math.nan:>5.2f} {max(e, default=math.nan):>5.2f}")


_SIGNALS: tuple[tuple[str, str], ...] = (
    ("pred", "distance from the position the last two fixes' motion predicts, px"),
    ("last", "distance from the last fix, px"),
    ("dtheta", "the fit's theta against the last fix's, deg (absolute)"),
    ("score", "the template's correlation (the fit's score), 1"),
    ("ratio", "mismatch ratio: 1 - score over the recent fixes' median, 1"),
    ("sigma", "sigma: sigma_factor times the fit's worst standard deviation, px"),
    ("cover", "share of the template's weight inside the frame, 1"),
    ("again", "1: a candidate of the whole frame's search (rules for a tip found again), 0: near the last fix"),
    ("near", "the edges' contrast right behind the tip (EdgeCheck.near), 1"),
    ("far", "the edges' contrast further back (EdgeCheck.far), 1"),
    ("nf", "near over far, 1"),
    ("shape", "the edges' profiles' correlation (EdgeCheck.shape), 1"),
)
"""The signals ``--vouch-signals`` reads on each candidate "nothing vouches" refused: key, meaning and unit."""


_BORDER: tuple[tuple[str, str], ...] = (
    ("axis", "length of the axis read, from 2 px behind the fit to 2 px inside the border, px"),
    ("run", "share of it whose middle is needle (the outline continues to the border), 1"),
    ("gap", "the longest stretch of it whose middle is not needle, px"),
    ("turn", "the largest narrowing of the needle's run going back (a needle only widens), px"),
    ("dw", "median width less the first frame's as far behind its tip, px"),
)
"""``--border-signals``: the outline behind the fit read across the axis every 2 px up to the border."""


def _border_run(image: np.ndarray, x: float, y: float, u: tuple[float, float], ground: tuple[float, float],
                contrast: float) -> list[tuple[float, bool, float]]:
    """Across the axis from ``(x, y)`` back along ``u``, every 2 px to 2 px inside the field's border: the
    distance behind the tip (px), whether the axis there is needle (the profile, smoothed by 1 px, standing
    ``contrast`` ground spreads from the ground's level, gaps of 12 px closed as the shaft's walk does), and
    the needle's run across through the axis (px; NaN when the run reaches the frame's edge)."""
    from scipy import ndimage

    from stickslip.vision.shaft import station_profiles

    H, W = image.shape
    ux, uy = u
    nx, ny = -uy, ux
    ts = np.arange(-48.0, 48.0 + 1e-9)
    mid = ts.size // 2
    out: list[tuple[float, bool, float]] = []
    s = 2.0
    while True:
        px, py = x + s * ux, y + s * uy
        if min(px, py, W - 1 - px, H - 1 - py) < 2.0 or s > 400:
            return out
        raw, ok = station_profiles(image, x, y, s * ux + ts * nx, s * uy + ts * ny, ux, uy)
        sm = ndimage.gaussian_filter1d(raw, 1.0, mode="nearest")
        on = (np.abs(sm - ground[0]) > contrast * ground[1]) & ok
        on = ndimage.binary_closing(on, np.ones(13, dtype=bool)) & ok
        near = np.flatnonzero(on[mid - 2 : mid + 3])
        if near.size == 0:
            out.append((s, False, math.nan))
        else:
            lo = hi = mid - 2 + int(near[0])
            while lo > 0 and on[lo - 1]:
                lo -= 1
            while hi < on.size - 1 and on[hi + 1]:
                hi += 1
            bounded = lo > 0 and hi < on.size - 1 and bool(ok[lo - 1]) and bool(ok[hi + 1])
            out.append((s, True, float(hi - lo + 1) if bounded else math.nan))
        s += 2.0


def _border_signals(t: TipTracker, cand: Any, image: np.ndarray, first: list[tuple[float, bool, float]]
                    ) -> dict[str, float]:
    """:data:`_BORDER` for a candidate (``first``: :func:`_border_run` of the first frame at its tip)."""
    r = cand.ref
    c, s_ = math.cos(r.theta), math.sin(r.theta)
    ux, uy = t.template.shaft
    run = _border_run(image, r.x, r.y, (c * ux - s_ * uy, s_ * ux + c * uy), t.template.ground, t.params.contrast)
    if not run:
        return {"axis": 0.0, "run": math.nan, "gap": math.nan, "turn": math.nan, "dw": math.nan}
    on = [o for _, o, _ in run]
    gap = best = 0
    for o in on:
        gap = 0 if o else gap + 1
        best = max(best, gap)
    w = [v for _, _, v in run if math.isfinite(v)]
    turn = max((w[i] - min(w[i + 1 :]) for i in range(len(w) - 1)), default=math.nan)
    w0 = {s: v for s, _, v in first}
    dw = [v - w0[s] for s, _, v in run if math.isfinite(v) and math.isfinite(w0.get(s, math.nan))]
    return {"axis": run[-1][0], "run": float(np.mean(on)), "gap": 2.0 * best, "turn": max(turn, 0.0),
            "dw": float(np.median(dw)) if dw else math.nan}


def border_signals(n_own: int) -> None:
    """Tabulate :data:`_BORDER` on the own round and lobed modes' candidates "nothing vouches" refused (the
    round mode's sets at seeds 0, 2 and 1, 3 (wide), the lobed mode's wide set): good (3 px or less from the
    truth) against wrong, near the last fix and found again."""
    wide = {"size": 256, "widths": (14.0, 18.0), "looks": ("optical",)}
    rows: list[tuple[str, float, dict[str, float]]] = []
    for make, kw in ((round_benchmark, {"seed": 0, "size": 256}), (round_benchmark, {"seed": 2, "size": 256}),
                     (round_benchmark, {"seed": 1, **wide}), (round_benchmark, {"seed": 3, **wide}),
                     (lobed_benchmark, {"seed": 1, **wide})):
        rows += _unvouched(make(n_own, 40, **kw), "own", border=True)  # type: ignore[operator]
    keys = [k for k, _ in _BORDER]
    for again in (0.0, 1.0):
        mine = [r for r in rows if r[2]["again"] == again]
        good = [r for r in mine if r[1] <= 3.0]
        wrong = [r for r in mine if r[1] > 3.0]
        print(f"\n{'found again' if again else 'near the last fix'}: {len(good)} good, {len(wrong)} wrong")
        for key, what in _BORDER:
            g = np.array([r[2][key] for r in good])
            b = np.array([r[2][key] for r in wrong])
            fg = g[np.isfinite(g)]
            print(f"  {key}: {what}\n    good: " + (f"{fg.min():.3g} {np.median(fg):.3g} {fg.max():.3g} ({fg.size})"
                                                  if fg.size else "none") + f"; {_separation(g, b)}")
        for r in sorted(wrong, key=lambda r: -r[1]):
            print(f"    wrong {r[1]:5.1f} px: " + ", ".join(f"{k} {r[2][k]:.3g}" for k in keys)
                  + f", sigma {r[2]['sigma']:.2f}")


def _predicted(fixes: list[tuple[int, float, float]], k: int) -> tuple[float, float]:
    """Where the last two fixes' motion puts the tip in frame ``k`` (the last fix alone: there)."""
    k2, x2, y2 = fixes[-1]
    if len(fixes) < 2:
        return x2, y2
    k1, x1, y1 = fixes[-2]
    a = (k - k2) / max(k2 - k1, 1)
    return x2 + a * (x2 - x1), y2 + a * (y2 - y1)


def _unvouched(seqs: Sequence[object], group: str, border: bool = False
               ) -> list[tuple[str, float, dict[str, float]]]:
    """Track ``seqs``; for every candidate refused by "nothing vouches" (near the last fix or in the whole
    frame), its group, distance from the truth (px) and :data:`_SIGNALS`. The tracker is run as it is: its
    ``_judge`` is wrapped on the instance to record what it refused, every decision unchanged."""
    out: list[tuple[str, float, dict[str, float]]] = []
    for seq in seqs:
        frames = seq.frames  # type: ignore[attr-defined]
        images = [as_image(f.image) for f in frames]
        try:
            tracker = TipTracker(images[0], frames[0].tip, PARAMS)
        except TemplateError:
            continue
        fixes: list[tuple[int, float, float]] = [(0, *frames[0].tip)]
        judge = tracker._judge
        first = (_border_run(images[0], *frames[0].tip, tracker.template.shaft, tracker.template.ground,
                             tracker.params.contrast) if border else [])
        now = {"k": 0}

        def watched(cand: Any, image: np.ndarray, reacquire: bool = False, *, t: TipTracker = tracker,
                    judge: Any = judge, fixes: list[tuple[int, float, float]] = fixes,
                    now: dict[str, int] = now, frames: Any = frames,
                    first: list[tuple[float, bool, float]] = first) -> Any:
            res, cand = judge(cand, image, reacquire)
            if isinstance(res, Lost) and "nothing vouches" in res.detail:
                d, sig = _signals(t, cand, fixes, now["k"], frames[now["k"]].tip)
                more = _border_signals(t, cand, image, first) if border else {}
                out.append((group, d, {**sig, **more, "again": float(reacquire)}))
            return res, cand

        tracker._judge = watched  # type: ignore[method-assign]
        for k, img in enumerate(images[1:], start=1):
            now["k"] = k
            r = tracker.update(img)
            if isinstance(r, Fix):
                fixes.append((k, r.x, r.y))
    return out


def _signals(t: TipTracker, cand: Any, fixes: list[tuple[int, float, float]], k: int,
             tip: tuple[float, float]) -> tuple[float, dict[str, float]]:
    """A refused candidate's distance from ``tip`` (px) and its :data:`_SIGNALS`."""
    r, p = cand.ref, t.params
    px, py = _predicted(fixes, k)
    usual = t._usual_mismatch()
    ec = cand.edges
    nan = math.nan
    s = {"pred": math.hypot(r.x - px, r.y - py), "last": math.hypot(r.x - fixes[-1][1], r.y - fixes[-1][2]),
         "dtheta": abs(math.degrees(r.theta - t._theta)), "score": r.score,
         "ratio": (1.0 - r.score) / (usual if usual else t._first_mismatch),
         "sigma": p.sigma_factor * r.sigma, "cover": r.coverage,
         "near": ec.near if ec else nan, "far": ec.far if ec else nan,
         "nf": ec.near / ec.far if ec and ec.far > 0 else nan, "shape": ec.shape if ec else nan}
    return math.hypot(r.x - tip[0], r.y - tip[1]), s


def _separation(good: np.ndarray, bad: np.ndarray) -> str:
    """Whether one threshold separates ``bad`` from ``good``: the side and the gap, or, for the threshold
    that refuses every one of ``bad`` at the least cost, how many of ``good`` it refuses too."""
    good, bad = good[np.isfinite(good)], bad[np.isfinite(bad)]
    if good.size == 0 or bad.size == 0:
        return "-"
    if bad.min() > good.max():
        return f"yes, wrong above by {bad.min() - good.max():.3g}"
    if bad.max() < good.min():
        return f"yes, wrong below by {good.min() - bad.max():.3g}"
    above, below = int(np.sum(good >= bad.min())), int(np.sum(good <= bad.max()))
    return f"no: refusing all wrong refuses {min(above, below)} of {good.size} good"


def _pairs(groups: dict[str, list[tuple[str, float, dict[str, float]]]]) -> None:
    """For each pair of :data:`_SIGNALS`, the good candidates inside the wrong ones' box (both signals within the
    wrong ones' range): what refusing that box, the least a two-signal rule must refuse, would cost. The best
    five pairs are printed (with so few wrong ones, some pair's box is empty by chance more easily than one
    signal's range)."""
    good = groups["peer good"] + groups["own good"]
    wrong = groups["peer wrong"] + groups["own wrong"]
    if not wrong:
        return
    keys = [k for k, _ in _SIGNALS]
    out = []
    for i, a in enumerate(keys):
        for b in keys[i + 1 :]:
            box = [(min(r[2][k] for r in wrong), max(r[2][k] for r in wrong)) for k in (a, b)]
            inside = [r for r in good if all(lo <= r[2][k] <= hi for k, (lo, hi) in zip((a, b), box, strict=True))]
            tested = sum(math.isfinite(r[2][a]) and math.isfinite(r[2][b]) for r in good)
            out.append((len(inside), a, b, sum(r[0] == "peer" for r in inside), tested))
    print("\npairs: good candidates inside the wrong ones' box (peer among them), of those\nwith both signals")
    for n, a, b, n_peer, tested in sorted(out)[:5]:
        print(f"  {a:>6} and {b:<6}: {n:>3} ({n_peer} peer) of {tested}")


def vouch_signals(n_peer: int, n_own: int) -> None:
    """Tabulate :data:`_SIGNALS` on the candidates "nothing vouches" refused: the second renderer's (all
    near the truth) against the own round and lobed modes' (those more than 3 px off are the wrong fixes the
    rule exists for)."""
    rows = _unvouched(peer_benchmark(n_peer, 50, seed=0, size=512), "peer")
    wide = {"seed": 1, "size": 256, "widths": (14.0, 18.0), "looks": ("optical",)}
    for make, kw in ((round_benchmark, {"seed": 0, "size": 256}), (round_benchmark, wide),
                     (lobed_benchmark, wide)):
        rows += _unvouched(make(n_own, 40, **kw), "own")  # type: ignore[operator]
    groups = {f"{g} {v}": [r for r in rows if r[0] == g and (r[1] <= 3.0) == (v == "good")]
              for g in ("peer", "own") for v in ("good", "wrong")}
    # the like-for-like part: every wrong one was a fit near the last fix (the whole frame's candidates have
    # passed the stricter rules for a tip found again, sigma among them)
    groups["peer, local"] = [r for r in groups["peer good"] if not r[2]["again"]]
    groups["own, local"] = [r for r in groups["own good"] if not r[2]["again"]]
    for g, rs in groups.items():
        e = [r[1] for r in rs]
        print(f"{g:>10}: {len(rs)} candidates" + (f", {min(e):.2f} to {max(e):.2f} px from the truth" if e else ""))
    print("\nranges (min, median, max); separation of the wrong from the peer's and from\nall good ones")
    for key, what in _SIGNALS:
        print(f"\n{key}: {what}")
        vals = {g: np.array([r[2][key] for r in rs]) for g, rs in groups.items()}
        for g, v in vals.items():
            f = v[np.isfinite(v)]
            print(f"  {g:>10}: " + (f"{f.min():8.3g} {np.median(f):8.3g} {f.max():8.3g}  ({f.size})" if f.size
                                   else "none"))
        wrong = np.concatenate([vals["peer wrong"], vals["own wrong"]])
        print(f"  wrong against peer good: {_separation(vals['peer good'], wrong)}")
        print(f"  against peer good, local: {_separation(vals['peer, local'], wrong)}")
        local = np.concatenate([vals["peer, local"], vals["own, local"]])
        print(f"  against all good, local: {_separation(local, wrong)}")
        print(f"  against all good: {_separation(np.concatenate([vals['peer good'], vals['own good']]), wrong)}")
    _pairs(groups)
    print("\nthe wrong ones:")
    for r in groups["peer wrong"] + groups["own wrong"]:
        print(textwrap.fill(f"  {r[0]} {r[1]:5.1f} px: " + ", ".join(f"{k} {v:.3g}" for k, v in r[2].items()),
                            80, subsequent_indent=" " * 4))


def _lobed_class(f: OwnFrame, image_size: int) -> str:
    """What a lobed-mode frame is, for the tally: its kind, cause, and a visible tip's room to the edge."""
    kind, cause = f.kind, f.cause
    if kind == "occluded":
        return {"lobed": "occluded by a lobed grain", "flake": "occluded by a flake", "bead": "occluded by a bead",
                "bead-edge": "bead, shaft leaving the field"}.get(cause, "occluded by a disc")
    if kind != "visible":
        return kind
    if cause == "shaft-edge":
        return "visible, shaft leaving the field"
    x, y = f.tip
    room = min(x, y, image_size - 1 - x, image_size - 1 - y)
    return "visible, 4-10 px inside" if room < 10.0 else "visible, 10+ px inside"


def _tally(seqs: Sequence[Any], what: Callable[[Any, Any], str], name: Callable[[Any], str]
           ) -> tuple[dict[tuple[str, str], int], list[tuple[float, int, int, str, float, str]], list[float]]:
    """Track every sequence from its first frame's tip: the verdicts tallied by ``what`` a frame is, the
    fixes more than 3 px off (error, sequence, frame, what, tip width) and the visible tips' errors, px;
    ``name`` names a sequence (its look) in messages."""
    tally: dict[tuple[str, str], int] = {}
    bad: list[tuple[float, int, int, str, float, str]] = []
    errors: list[float] = []
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            tracker = TipTracker(images[0], seq.frames[0].tip, PARAMS)
        except TemplateError as exc:
            print(f"sequence {i} ({name(seq)}, tip {seq.width_px:.1f} px) not learnt: {exc}")
            continue
        judged = _watch(tracker)
        fixes: list[tuple[int, float, float]] = [(0, *seq.frames[0].tip)]
        for k, (f, img) in enumerate(zip(seq.frames[1:], images[1:], strict=True), start=1):
            pre = _state(tracker)
            judged.clear()
            r = tracker.update(img)
            w = what(f, img)
            verdict = "fix" if isinstance(r, Fix) else r.reason
            tally[(w, verdict)] = tally.get((w, verdict), 0) + 1
            if isinstance(r, Fix):
                e = math.hypot(r.x - f.tip[0], r.y - f.tip[1])
                if f.kind == "visible":
                    errors.append(e)
                if e > 3.0:
                    bad.append((e, i, k, w, seq.width_px, _details(_taken_by(tracker, pre, r, judged, fixes, k, f,
                                                                                img))))
                fixes.append((k, r.x, r.y))
    return tally, bad, errors


def _print_tally(seqs: Sequence[Any], tally: dict[tuple[str, str], int],
                 bad: list[tuple[float, int, int, str, float, str]],
                 errors: list[float], name: Callable[[Any], str], refused: str = "") -> None:
    """:func:`_tally`'s counts by kind of frame, the visible tips' errors and every fix more than 3 px off."""
    print(f"{len(seqs)} sequences ({', '.join(f'{name(s)} {s.width_px:.1f} px' for s in seqs)})")
    for what in sorted({w for w, _ in tally}):
        row = {v: n for (w, v), n in tally.items() if w == what}
        print(f"{what:>28}: {sum(row.values()):>4} frames; " + ", ".join(f"{v} {n}" for v, n in sorted(row.items())))
    e = np.array(errors) if errors else np.array([math.nan])
    print(f"visible tips: {refused}median error {np.median(e):.2f} px, 95th percentile {np.percentile(e, 95):.2f} px")
    print(f"fixes more than 3 px off: {len(bad)}" + (f", worst {max(bad)[0]:.1f} px" if bad else ""))
    for err, i, k, what, w, why in sorted(bad, reverse=True):
        print(f"  {err:6.1f} px  sequence {i} frame {k}: {what}, tip {w:.1f} px, {name(seqs[i])}")
        print(textwrap.fill(why, 100, initial_indent=" " * 6, subsequent_indent=" " * 6))


def lobed(n_frames: int, wide: bool = False, flake: bool = False, plain: int | None = None,
          bead: bool = False, droplet: bool = False) -> int:
    """Track the own renderer's lobed-mode frames; the number of fixes more than 3 px off.

    ``wide``: bright field only, tips 14 to 18 px wide (seed 1), as the second renderer's
    worst fixes were; else tips 3 to 20 px, both looks (seed 0). ``flake``: the flake
    mode's frames instead; ``bead``: the round mode's; ``droplet``: the droplet mode's; ``plain``: the plain
    frames of that seed instead.
    """
    make = (flake_benchmark if flake else round_benchmark if bead else droplet_benchmark if droplet
            else lobed_benchmark)
    seqs = (own_benchmark(n_frames, 40, seed=plain, size=256, defocus=DEFOCUS) if plain is not None
            else make(n_frames, 40, seed=1, size=256, widths=(14.0, 18.0), looks=("optical",), defocus=DEFOCUS)
            if wide else make(n_frames, 40, seed=0, size=256, defocus=DEFOCUS))
    tally, bad, errors = _tally(seqs, lambda f, img: _lobed_class(f, img.shape[1]), lambda s: str(s.look))
    _print_tally(seqs, tally, bad, errors, lambda s: str(s.look))
    return len(bad)


def micrographs(n_seq: int) -> dict[str, tuple[int, int, int]]:
    """Track the micrograph mode's six sets; per set the visible tips refused, the visible tips and the wrong
    fixes (more than 3 px off or on a hidden tip). Empty without scikit-image."""
    out: dict[str, tuple[int, int, int]] = {}
    for ground in ("micro", "retina"):
        for seed in (1, 2, 3):
            seqs = micrograph_benchmark(ground, seed, n_seq, defocus=DEFOCUS)
            if not seqs:
                print("the micrograph mode skipped: scikit-image (the dev extra, which ships the files) is missing")
                return out
            print(f"\n{ground} {seed}: the own renderer over {ground}'s ground, seed {seed}")
            tally, bad, errors = _tally(seqs, lambda f, img: _lobed_class(f, img.shape[1]),
                                        lambda s: f"{s.photons:.0f} photons")
            visible = sum(n for (w, _), n in tally.items() if w.startswith("visible"))
            refused = sum(n for (w, v), n in tally.items() if w.startswith("visible") and v != "fix")
            hidden = sum(n for (w, v), n in tally.items() if not w.startswith("visible") and v == "fix")
            wrong = hidden + sum(1 for b in bad if b[3].startswith("visible"))
            _print_tally(seqs, tally, bad, errors, lambda s: f"{s.photons:.0f} photons",
                         f"{refused} of {visible} refused; ")
            out[f"{ground} {seed}"] = (refused, visible, wrong)
    print("\nset: visible tips refused / visible, wrong fixes (more than 3 px off or on a hidden tip)")
    for name, (refused, visible, wrong) in out.items():
        print(f"  {name:<9} {refused:>4} / {visible:>4}, {wrong}")
    return out


def scenes(n_frames: int, seed: int = 0, widths: tuple[float, float] = (6.0, 22.0)) -> tuple[int, int, int]:
    """Track the third generator's frames (:mod:`occlusion_scenes`); the fixes more than 3 px off, the visible
    tips refused and the visible tips."""
    seqs = scene_benchmark(n_frames, 30, seed=seed, size=256, widths=widths)
    def name(s: Any) -> str:
        return f"{s.shape} {s.psf}"
    tally, bad, errors = _tally(seqs, lambda f, img: f"{f.kind}, {f.cause or 'clear'}", name)
    visible = sum(n for (w, _), n in tally.items() if w.startswith("visible"))
    refused = sum(n for (w, v), n in tally.items() if w.startswith("visible") and v != "fix")
    _print_tally(seqs, tally, bad, errors, name, f"{refused} of {visible} refused; ")
    return len(bad), refused, visible


def _split(fix: Fix, tip: tuple[float, float], shaft: tuple[float, float]) -> tuple[float, float]:
    """A fix's error along the needle's axis (positive: behind the tip, up the shaft) and across it (positive:
    the axis turned by +90 deg, x right and y down), px; the axis is the template's shaft direction turned by
    the fix's angle."""
    c, s = math.cos(fix.angle), math.sin(fix.angle)
    ux, uy = c * shaft[0] - s * shaft[1], s * shaft[0] + c * shaft[1]
    ex, ey = fix.x - tip[0], fix.y - tip[1]
    return ex * ux + ey * uy, -ex * uy + ey * ux


def _split_rows(seqs: Sequence[Any], label: str) -> list[tuple[str, int, float, float, float, float, float, float]]:
    """Every visible tip's fix: (set, sequence, along, across, the frame's blur against the first frame's (signed
    sigma, px), the copy's blur, px, the error, px, the fix's turn, deg)."""
    rows = []
    for i, seq, tracker, images in learnt_sequences(seqs, PARAMS):
        b0 = seq.frames[0].blur
        for f, img in zip(seq.frames[1:], images[1:], strict=True):
            r = tracker.update(img)
            if isinstance(r, Fix) and f.kind == "visible":
                along, across = _split(r, f.tip, tracker.template.shaft)
                rel = math.copysign(math.sqrt(abs(f.blur**2 - b0**2)), f.blur - b0)
                rows.append((label, i, along, across, rel, r.blur, math.hypot(along, across), math.degrees(r.angle)))
    return rows


def _split_line(name: str, a: np.ndarray) -> str:
    """n, median error, along: mean and sd, across: mean and sd, the along bias over the error's RMS."""
    if a.size == 0:
        return f"{name:<26} {0:>4}"
    al, ac = a[:, 0], a[:, 1]
    rms = math.sqrt(float(np.mean(al**2 + ac**2)))
    return (f"{name:<26} {len(a):>4} {np.median(np.hypot(al, ac)):>5.2f} {al.mean():>+6.2f} {al.std():>5.2f} "
            f"{ac.mean():>+6.2f} {ac.std():>5.2f} {rms:>5.2f}")


def error_split(n_peer: int, n_own: int) -> None:
    """The visible tips' errors split along the needle's axis and across it, by sequence and by blur."""
    sets: list[tuple[str, Sequence[Any]]] = [
        ("peer", peer_benchmark(n_peer, 50, seed=0, size=512)),
        ("own plain", own_benchmark(n_own, 40, seed=0, size=256)),
        ("own lobed", lobed_benchmark(n_own, 40, seed=0, size=256)),
        ("own round", round_benchmark(n_own, 40, seed=0, size=256)),
    ]
    head = (f"{'':<26} {'n':>4} {'med':>5} {'along':>6} {'sd':>5} {'across':>6} {'sd':>5} {'rms':>5}")
    print("px; along: + behind the tip (up the shaft); mean (bias) and sd of each component")
    for label, seqs in sets:
        rows = _split_rows(seqs, label)
        a = np.array([r[2:] for r in rows]).reshape(-1, 6)
        print(f"\n{label}: look, tip width px, photons; the sequence's blur range px\n{head}")
        for i, seq in enumerate(seqs):
            mine = a[[r[1] == i for r in rows]] if len(a) else a
            if len(mine):
                blur = [f.blur for f in seq.frames[1:] if f.kind == "visible"]
                name = (f"{i} {seq.look[:3]} {seq.width_px:4.1f} {seq.photons:3.0f} "
                        f"{min(blur):.1f}-{max(blur):.1f}")
                print(_split_line(name, mine))
        print(_split_line("all", a))
        print("by the frame's blur against the first frame's (signed sigma, px)")
        for lo, hi in ((-9, -1.5), (-1.5, -0.5), (-0.5, 0.5), (0.5, 1.5), (1.5, 9)):
            print(_split_line(f"  {lo:+.1f} to {hi:+.1f}", a[(a[:, 2] >= lo) & (a[:, 2] < hi)]))
        print("by the copy's blur less the frame's (px): the copy lags the focus")
        for lo, hi in ((-9, -1.0), (-1.0, -0.3), (-0.3, 0.3), (0.3, 1.0), (1.0, 9)):
            d = a[:, 3] - a[:, 2]
            print(_split_line(f"  {lo:+.1f} to {hi:+.1f}", a[(d >= lo) & (d < hi)]))
        print("by the needle's turn since the first frame (the fix's angle, deg)")
        for lo, hi in ((-90, -2), (-2, -0.5), (-0.5, 0.5), (0.5, 2), (2, 90)):
            print(_split_line(f"  {lo:+.1f} to {hi:+.1f}", a[(a[:, 5] >= lo) & (a[:, 5] < hi)]))


class _Recording:
    """The simulated arm, with its true position before and after every burst."""

    def __init__(self, sim: SimulatedMM3A) -> None:
        self.sim = sim
        self.bursts: list[tuple[int, int, float, float]] = []

    @property
    def info(self) -> DeviceInfo:
        return self.sim.info

    @property
    def pose(self):  # type: ignore[no-untyped-def]
        return self.sim.pose

    @property
    def clock_s(self) -> float:
        return self.sim.clock_s

    def step(self, joint: int, n: int) -> None:
        q0 = self.sim.position(joint)
        self.sim.step(joint, n)
        self.bursts.append((joint, n, q0, self.sim.position(joint)))

    def position(self, joint: int) -> float:
        return self.sim.position(joint)

    def set_frequency(self, joint: int, hz: float) -> None:
        self.sim.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        return self.sim.frequency(joint)

    def stop(self, joint: int | None = None) -> None:
        self.sim.stop(joint)

    def settings(self) -> dict[str, object]:
        return self.sim.settings()

    def close(self) -> None:
        self.sim.close()


def calibration(seeds: int = 5) -> list[float]:
    errs: list[float] = []
    print(f"{'look':>8} {'arm':>4} {'joint':>5} {'dir':>3} {'steps':>5} {'measured':>12} {'realized':>12} "
          f"{'error':>8} {'sd':>6}")
    for look in ("optical", "sem"):
        for seed in range(seeds):
            sim = SimulatedMM3A(seed=100 + seed)
            dev = _Recording(sim)
            cam = SimCamera(dev, SimCamSettings(look=look, seed=seed, photons=200))  # type: ignore[arg-type]
            truth, _ = cam.true_tip()
            res = calibrate_camera(dev, cam, sim.pose, joints=(3, 1), tip=(float(truth[0]), float(truth[1])))
            seen: dict[tuple[int, int], int] = {}
            for jr in res.joints:
                if jr.refused:
                    print(f"{look:>8} {seed:>4} {jr.joint:>5} refused: {jr.refused}")
                    continue
                for fit, s in zip(jr.fits, jr.step_sizes, strict=True):
                    sign = 1 if s.direction == "+" else -1
                    mine = [b for b in dev.bursts if b[0] == jr.joint and np.sign(b[1]) == sign]
                    k0 = seen.get((jr.joint, sign), 0)
                    moves = mine[k0 : k0 + len(fit.steps) - 1]
                    seen[(jr.joint, sign)] = k0 + len(fit.steps) - 1
                    realized = sum(abs(b[3] - b[2]) for b in moves) / sum(abs(b[1]) for b in moves)
                    err = s.gamma / realized - 1
                    errs.append(err)
                    unit, k = ("nm", 1e9) if jr.joint == 3 else ("urad", 1e6)
                    print(f"{look:>8} {seed:>4} {jr.joint:>5} {s.direction:>3} {s.steps:>5} "
                          f"{s.gamma * k:>9.2f} {unit:>2} {realized * k:>9.2f} {unit:>2} {100 * err:>+7.2f}% "
                          f"{100 * s.sigma / s.gamma:>5.2f}%")
    a = np.abs(np.array(errs))
    print(f"step size error: median {100 * np.median(a):.2f} %, largest {100 * a.max():.2f} % (issue: within 1 %), "
          f"{int(np.sum(a <= 0.01))}/{a.size} within 1 %")
    return errs


_OWN_MODES: dict[str, tuple[str, int, dict[str, bool]]] = {
    "--lobed": ("frames with lobed grains and tips near the edge", 400, {}),
    "--flake": ("frames with flat chips stuck on the tip", 200, {"flake": True}),
    "--round": ("blunt needles with round beads and tips near the edge", 200, {"bead": True}),
    "--droplet": ("transparent droplets clinging to the tip (bright field)", 200, {"droplet": True}),
}
"""The own renderer's modes: what they show, their default number of frames, and :func:`lobed`'s options."""


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(args, ["--params", "--seed", "--scenes", "--plain", "--vouch-signals", "--error-split",
                       "--border-signals", "--refusals", "--tracking-only", "--micrograph", "--defocus", *_OWN_MODES],
                __doc__)
    if "--params" in args:  # the tracker's constants changed, e.g. --params mismatch_floor=0.03
        at = args.index("--params")
        _set_params(args[at + 1])
        print(f"tracker constants changed: {args[at + 1]}")
        args = args[:at] + args[at + 2 :]
    if "--defocus" in args:  # the own renderer's defocus in its modes: gaussian (default) or disc
        global DEFOCUS
        at = args.index("--defocus")
        DEFOCUS = args[at + 1]
        print(f"the own renderer's defocus: {DEFOCUS}")
        args = args[:at] + args[at + 2 :]
    seed: int | None = None
    if "--seed" in args:  # the held-out renderer's (or the third generator's) draw
        at = args.index("--seed")
        seed = int(args[at + 1])
        args = args[:at] + args[at + 2 :]
    numbers = [a for a in args if not a.startswith("--")]
    for flag, (what, default, kw) in _OWN_MODES.items():
        if flag in args:  # the mode on all tips, then on wide bright-field tips only
            n_own = int(numbers[0]) if numbers else default
            print(f"tip tracking on the own renderer's {what}")
            lobed(n_own, **kw)
            print("\nthe same, bright field only, tips 14 to 18 px wide")
            lobed(n_own, wide=True, **kw)
            return
    if "--micrograph" in args:
        print("tip tracking on the own renderer's frames over real micrographs (bright field)")
        micrographs(int(numbers[0]) if numbers else 40)
        return
    if "--scenes" in args:
        n_sc = int(numbers[0]) if numbers else 300
        if seed is not None:
            print(f"tip tracking on the third generator's occlusions, seed {seed}")
            scenes(n_sc, seed)
            return
        for seed in (0, 1):
            print(f"tip tracking on the third generator's occlusions, seed {seed}")
            scenes(n_sc, seed)
            print()
        print("the same, blunt tips 12 to 22 px wide, seed 2")
        scenes(n_sc, 2, (12.0, 22.0))
        return
    if "--plain" in args:
        for seed in (0, 1, 2):
            if seed:
                print()
            print(f"tip tracking on the own renderer's plain frames, seed {seed}")
            lobed(int(numbers[0]) if numbers else 400, plain=seed)
        return
    n = int(numbers[0]) if numbers else 500
    if "--vouch-signals" in args:
        print('the signals behind the candidates "nothing vouches" refused')
        vouch_signals(n, int(numbers[1]) if len(numbers) > 1 else 200)
        return
    if "--error-split" in args:
        print("the visible tips' errors along the needle's axis and across it")
        error_split(n, int(numbers[1]) if len(numbers) > 1 else 200)
        return
    if "--border-signals" in args:
        print('the outline up to the border behind the candidates "nothing vouches" refused')
        border_signals(int(numbers[0]) if numbers else 400)
        return
    if "--refusals" in args:
        print("the second renderer's refused visible tips, by the rule that refused them")
        refusals(n, seed or 0)
        return
    print("1. tip tracking on the second renderer's frames" + (f", draw {seed}" if seed is not None else ""))
    tracking(n, seed or 0)
    if "--tracking-only" in args:
        return
    print("\n2. step sizes measured by the camera (sim:// with simcam://, 0.5 um a pixel)")
    calibration()


if __name__ == "__main__":
    main()
