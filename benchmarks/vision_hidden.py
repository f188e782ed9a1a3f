"""The averaged template's fixes on hidden tips, side by side with main's, on the own sets (issue 30).

Every own set's sequences are tracked twice in one run, with the default constants and with
``average_frames`` set (8 unless told); every fix of either that is more than 3 px off, and every
fix the averaged run takes on a frame whose tip is not visible (occluded, defocused, out of the
field) that the default run does not take, is printed with what took it (``bench_vision._taken_by``:
the search near the last fix or the whole frame's, the copy, score, mismatch ratio, sigma, the
shaft's and the outline's readings), the recent mismatch median (the ratio's denominator) of both runs,
and the default run's verdict on that frame.

Usage (from the worktree): ``PYTHONPATH=tests/support nice .venv/bin/python benchmarks/vision_hidden.py
[SET ...] [--average N]``; the sets: plain0 plain1 plain2 lobed lobedwide flake flakewide round
roundwide droplet dropletwide scenes0 ... scenes4 (default: all); ``--texture SCALE``: the simulator's
substrate texture's contrast times SCALE (own sets only; the scenes draw their own ground).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "support"))

import numpy as np  # noqa: E402
from bench_vision import _state, _taken_by, _watch  # noqa: E402
from occlusion_scenes import scene_benchmark  # noqa: E402
from vision_own import (  # noqa: E402
    droplet_benchmark,
    flake_benchmark,
    lobed_benchmark,
    own_benchmark,
    round_benchmark,
)

import stickslip.sim.camera as sim_camera  # noqa: E402
from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.template import TemplateError, TrackerParams  # noqa: E402
from stickslip.vision.track import Fix, TipTracker  # noqa: E402

_WIDE: dict[str, Any] = {"seed": 1, "widths": (14.0, 18.0), "looks": ("optical",)}

SETS: dict[str, Callable[[], Sequence[Any]]] = {
    **{f"plain{s}": (lambda s=s: own_benchmark(400, 40, seed=s, size=256)) for s in (0, 1, 2)},
    "lobed": lambda: lobed_benchmark(400, 40, seed=0, size=256),
    "lobedwide": lambda: lobed_benchmark(400, 40, size=256, **_WIDE),
    "flake": lambda: flake_benchmark(200, 40, seed=0, size=256),
    "flakewide": lambda: flake_benchmark(200, 40, size=256, **_WIDE),
    "round": lambda: round_benchmark(200, 40, seed=0, size=256),
    "roundwide": lambda: round_benchmark(200, 40, size=256, **_WIDE),
    "droplet": lambda: droplet_benchmark(200, 40, seed=0, size=256),
    "dropletwide": lambda: droplet_benchmark(200, 40, size=256, **_WIDE),
    **{f"scenes{s}": (lambda s=s: scene_benchmark(300, 30, seed=s, size=256)) for s in range(5)},
}
"""The own sets as ``bench_vision.py``'s modes make them (the wide runs: bright field, tips 14 to 18 px)."""


MADE: list[int] = [0]
"""Sequences whose template the averaged run made again (the average collected and anchored)."""


def _run(seq: Any, images: list[Any], params: TrackerParams) -> list[tuple[Any, float, dict[str, Any] | None, float]]:
    """One sequence tracked with ``params``: per frame after the first (verdict, error px or nan, what took a fix
    more than 3 px off or on a hidden tip, the recent mismatch median before the frame)."""
    tracker = TipTracker(images[0], seq.frames[0].tip, params)
    bank0 = tracker.template.bank
    judged = _watch(tracker)
    fixes: list[tuple[int, float, float]] = [(0, *seq.frames[0].tip)]
    out: list[tuple[Any, float, dict[str, Any] | None, float]] = []
    for k, (f, img) in enumerate(zip(seq.frames[1:], images[1:], strict=True), start=1):
        pre = _state(tracker)
        usual = tracker._usual_mismatch() or tracker._first_mismatch
        judged.clear()
        r = tracker.update(img)
        e, d = math.nan, None
        if isinstance(r, Fix):
            e = math.hypot(r.x - f.tip[0], r.y - f.tip[1])
            if e > 3.0 or f.kind != "visible":
                d = _taken_by(tracker, pre, r, judged, fixes, k, f, img)
            fixes.append((k, r.x, r.y))
        out.append((r, e, d, usual))
    MADE[0] += tracker.template.bank is not bank0
    return out


def _line(d: dict[str, Any]) -> str:
    return ", ".join(f"{key} {v}" if isinstance(v, str) else f"{key} {v:.3g}" for key, v in d.items())


def compare(name: str, n_average: int) -> tuple[int, int, int, int]:
    """One set, default and averaged side by side; (hidden fixes default, averaged, > 3 px default, averaged)."""
    seqs = SETS[name]()
    base, avg = TrackerParams(), replace(TrackerParams(), average_frames=n_average)
    counts = [0, 0, 0, 0]
    MADE[0] = 0
    rows: list[str] = []
    for i, seq in enumerate(seqs):
        images = [as_image(f.image) for f in seq.frames]
        try:
            a, b = _run(seq, images, base), _run(seq, images, avg)
        except TemplateError:
            continue
        for k, (f, ra, rb) in enumerate(zip(seq.frames[1:], a, b, strict=True), start=1):
            hid = f.kind != "visible"
            fa, fb = isinstance(ra[0], Fix), isinstance(rb[0], Fix)
            counts[0] += fa and hid
            counts[1] += fb and hid
            counts[2] += fa and ra[1] > 3.0
            counts[3] += fb and rb[1] > 3.0
            new_hidden = fb and hid and not fa
            if (fb and rb[1] > 3.0) or new_hidden or (fa and ra[1] > 3.0):
                va = f"fix {ra[1]:.2f} px" if fa else ra[0].reason
                vb = f"fix {rb[1]:.2f} px" if fb else rb[0].reason
                head = (f"  seq {i} ({getattr(seq, 'look', getattr(seq, 'shape', ''))} {seq.width_px:.1f} px) "
                        f"frame {k} ({f.kind}{', ' + f.cause if getattr(f, 'cause', '') else ''}): default {va}, "
                        f"averaged {vb}; recent mismatch median {ra[3]:.4f} / {rb[3]:.4f}")
                for tag, r in (("default", ra), ("averaged", rb)):
                    if r[2] is not None:
                        head += f"\n    {tag}: " + _line(r[2])
                rows.append(head)
    print(f"{name}: fixes on hidden tips default {counts[0]}, averaged {counts[1]}; fixes > 3 px default "
          f"{counts[2]}, averaged {counts[3]}; the average made in {MADE[0]} of {len(seqs)} sequences")
    for r in rows:
        print(r)
    sys.stdout.flush()
    return counts[0], counts[1], counts[2], counts[3]


def _textured(scale: float) -> None:
    """The simulator's substrate with its texture's contrast times ``scale`` (the same random draws, so the
    same sequences otherwise): a structured ground, as a real micrograph behind the needle is, for this
    benchmark only."""
    plain = sim_camera._substrate

    def substrate(h: int, w: int, look: str, debris: int, rng: np.random.Generator) -> Any:
        state = rng.bit_generator.state
        base = plain(h, w, look, debris, rng)
        after = rng.bit_generator.state
        rng.bit_generator.state = state
        noise = rng.standard_normal((h, w))
        rng.bit_generator.state = after
        texture = sim_camera.ndimage.gaussian_filter(noise, 6.0) * 6.0 + sim_camera.ndimage.gaussian_filter(
            noise, 1.5) * 0.6
        texture = texture / (np.std(texture) + 1e-12)
        return base + (scale - 1.0) * (0.04 if look == "optical" else 0.05) * texture

    sim_camera._substrate = substrate


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    from cli_flags import check_flags  # the benchmarks folder: on the path when run as a script

    check_flags(args, ["--average", "--texture"], __doc__)
    n_average = 8
    if "--average" in args:
        at = args.index("--average")
        n_average = int(args[at + 1])
        args = args[:at] + args[at + 2 :]
    if "--texture" in args:
        at = args.index("--texture")
        _textured(float(args[at + 1]))
        print(f"the substrate's texture contrast times {args[at + 1]}")
        args = args[:at] + args[at + 2 :]
    for name in args or list(SETS):
        compare(name, n_average)


if __name__ == "__main__":
    main()
