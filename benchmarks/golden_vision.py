"""The tip tracker's golden comparison: the same frames give the same fixes and refusals, before and after a change.

A change to :mod:`stickslip.vision` that means to change no result (a speed-up) is checked
here, not by eye: ``record`` tracks the tip through a fixed set of sequences - the own
renderer's (``tests/support/vision_own.py``, 512 x 512) and the second renderer's
(``tests/support/vision_peer.py``, 512 x 512, the frames ``bench_vision.py`` tracks) - and
writes every answer to a JSON file: for a fix its x, y, score, sigma, blur and turn, for a
refusal its reason and detail. ``compare`` tracks them again and reports every difference
(floats: equal, or the largest difference; a fix against a refusal, or another reason,
is a changed decision).

Run ``python benchmarks/golden_vision.py record /tmp/golden_vision.json`` before a change and
``python benchmarks/golden_vision.py compare /tmp/golden_vision.json`` after it (about a
minute on one core; ``--frames N`` for another number of frames of each renderer, default 200).
Not a test: it is for refactorings.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "support"))

from vision_own import own_benchmark  # noqa: E402
from vision_peer import peer_benchmark  # noqa: E402

from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.track import Fix, TipTracker  # noqa: E402

FIELDS = ("x", "y", "score", "sigma", "blur", "angle")


def sequences(n_frames: int) -> list[tuple[str, list[Any], tuple[float, float]]]:
    """``(name, images, tip)`` for each sequence of both renderers."""
    out: list[tuple[str, list[Any], tuple[float, float]]] = []
    for i, s in enumerate(own_benchmark(n_frames, 40, seed=0, size=512)):
        out.append((f"own {i}", [as_image(f.image) for f in s.frames], s.frames[0].tip))
    for i, p in enumerate(peer_benchmark(n_frames, 50, seed=0, size=512)):
        out.append((f"peer {i}", [as_image(f.image) for f in p.frames], p.frames[0].tip))
    return out


def run(n_frames: int) -> tuple[dict[str, list[dict[str, Any]]], float, int]:
    """Every answer of every sequence, the tracker's CPU seconds and the frames tracked."""
    answers: dict[str, list[dict[str, Any]]] = {}
    cpu, n = 0.0, 0
    for name, images, tip in sequences(n_frames):
        c = time.process_time()
        tracker = TipTracker(images[0], tip)
        rows = []
        for img in images[1:]:
            r = tracker.update(img)
            if isinstance(r, Fix):
                rows.append({k: float(getattr(r, k)) for k in FIELDS})
            else:
                rows.append({"lost": r.reason, "detail": r.detail})
        cpu += time.process_time() - c
        n += len(images) - 1
        answers[name] = rows
    return answers, cpu, n


def compare(old: dict[str, list[dict[str, Any]]], new: dict[str, list[dict[str, Any]]]) -> int:
    """Print every difference; the number of changed decisions (fix or refusal, reason, detail)."""
    decisions, floats_differ, worst = 0, 0, 0.0
    for name in old:
        a, b = old[name], new.get(name, [])
        if len(a) != len(b):
            print(f"{name}: {len(a)} answers recorded, {len(b)} now")
            decisions += 1
            continue
        for k, (ra, rb) in enumerate(zip(a, b, strict=True)):
            if ("lost" in ra) != ("lost" in rb):
                decisions += 1
                print(f"{name} frame {k + 1}: {ra} -> {rb}")
            elif "lost" in ra:
                if ra != rb:
                    decisions += 1
                    print(f"{name} frame {k + 1}: {ra['lost']} ({ra['detail']}) -> {rb['lost']} ({rb['detail']})")
            else:
                for f in FIELDS:
                    if ra[f] != rb[f] and not (math.isnan(ra[f]) and math.isnan(rb[f])):
                        floats_differ += 1
                        d = abs(ra[f] - rb[f])
                        worst = max(worst, d if math.isfinite(d) else math.inf)
    total = sum(len(v) for v in old.values())
    fixes = sum(1 for v in old.values() for r in v if "lost" not in r)
    print(f"{total} answers ({fixes} fixes, {total - fixes} refusals): {decisions} decisions changed, "
          f"{floats_differ} fix values differ (largest difference {worst:.3g})")
    return decisions + floats_differ


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("action", choices=("record", "compare"))
    ap.add_argument("path", type=Path)
    ap.add_argument("--frames", type=int, default=200, help="frames of each renderer (default 200)")
    a = ap.parse_args(argv)
    if a.action == "record":
        answers, cpu, n = run(a.frames)
        a.path.write_text(json.dumps({"frames": a.frames, "answers": answers}))
        print(f"recorded {n} answers to {a.path} (tracker: {n / cpu:.0f} frames/s CPU)")
        return 0
    old = json.loads(a.path.read_text())
    answers, cpu, n = run(int(old["frames"]))
    print(f"tracked {n} frames: {n / cpu:.0f} frames/s CPU")
    return 1 if compare(old["answers"], answers) else 0


if __name__ == "__main__":
    sys.exit(main())
