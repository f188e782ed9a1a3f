"""The tip tracker before and after it was made faster, side by side in one run (frames/s and their ratio).

The tracker as it was before the speed-ups (the modules of :mod:`stickslip.vision` that it
is made of, at commit :data:`BEFORE`, read from this repository's history with ``git show``)
is kept as the comparator: both track the same sequences in turns (before, after, before,
...; each sequence's first frame gives the tip), on one core, and every answer of the two
is compared (a fix's x, y, score, sigma, blur and turn, a refusal's reason and detail: the
speed-ups change no result, ``benchmarks/golden_vision.py`` checks the same over more
frames). The frames are the second renderer's that ``bench_vision.py`` tracks
(``tests/support/vision_peer.py``) and the own renderer's (``tests/support/vision_own.py``),
512 x 512; the rendering is not counted. Printed: frames per second by the wall clock and
by the process's CPU time (on a shared machine the CPU time is the tracker's own cost),
before and after, and the ratios.

Run: ``.venv/bin/python benchmarks/bench_vision_speed.py [FRAMES] [--before REV]`` (FRAMES of
each renderer, default 100; ``--before`` another commit as the comparator, e.g. the one
before a single speed-up to measure it alone). Needs git and this repository's history.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "support"))

from vision_own import own_benchmark  # noqa: E402
from vision_peer import peer_benchmark  # noqa: E402

from stickslip.vision.frame import as_image  # noqa: E402
from stickslip.vision.template import TemplateError  # noqa: E402
from stickslip.vision.track import TipTracker  # noqa: E402

BEFORE = "e5a6c35"
"""The last commit with the tracker as it was before the speed-ups."""

MODULES = ("frame", "sampling", "template", "refine", "edges", "shaft", "width", "average", "confirm", "track")
"""The modules the tracker is made of (they import one another relatively)."""

LATER = ("sampling", "shaft", "width", "average", "confirm")
"""Modules added after :data:`BEFORE`: skipped at a commit that lacks them (its tracker does not import them)."""

FIELDS = ("x", "y", "score", "sigma", "blur", "angle")


def load_before(rev: str, where: Path) -> Any:
    """The tracker class at commit ``rev``: its modules copied from git into a package under ``where``."""
    pkg = where / "_vision_before"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for m in MODULES:
        path = f"{rev}:src/stickslip/vision/{m}.py"
        if m in LATER and subprocess.run(["git", "-C", str(ROOT), "cat-file", "-e", path],
                                         capture_output=True).returncode != 0:
            continue  # not there yet at that commit
        text = subprocess.run(["git", "-C", str(ROOT), "show", path],
                              capture_output=True, text=True, check=True).stdout
        (pkg / f"{m}.py").write_text(text)
    sys.path.insert(0, str(where))
    return importlib.import_module("_vision_before.track").TipTracker


def answer(r: Any) -> tuple[Any, ...]:
    if hasattr(r, "reason"):
        return ("lost", r.reason, r.detail)
    return tuple(float(getattr(r, k)) for k in FIELDS)


def run(tracker_cls: Any, images: list[Any], tip: tuple[float, float]) -> tuple[list[tuple[Any, ...]], float, float]:
    """Every answer of one sequence, and the tracker's wall and CPU seconds over the frames after the first."""
    tr = tracker_cls(images[0], tip)
    t, c = time.perf_counter(), time.process_time()
    res = [tr.update(im) for im in images[1:]]
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    return [answer(r) for r in res], wall, cpu


def _frames(text: str) -> int:
    n = int(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text}: needs at least 1 frame")
    return n


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="bench_vision_speed.py",
        description="The tip tracker at an earlier commit (before) and now (after), side by side in one run: "
        "frames/s by wall clock and by CPU time, their ratios, and how many answers differ (exit 1 if any "
        "does: a speed-up changes no answer).",
    )
    parser.add_argument("frames", nargs="?", type=_frames, default=100,
                        help="frames of each renderer (the second's and the own), 512 x 512 (default 100)")
    parser.add_argument("--before", default=BEFORE, metavar="REV",
                        help=f"the commit whose tracker is the comparator (default {BEFORE}); e.g. the one before "
                        "a single speed-up, to measure it alone")
    opts = parser.parse_args(argv)
    rev, n = opts.before, opts.frames
    seqs = [("peer", [as_image(f.image) for f in s.frames], s.frames[0].tip)
            for s in peer_benchmark(n, 50, seed=0, size=512)]
    seqs += [("own", [as_image(f.image) for f in s.frames], s.frames[0].tip)
             for s in own_benchmark(n, 40, seed=0, size=512)]
    with tempfile.TemporaryDirectory() as tmp:
        try:
            old_cls = load_before(rev, Path(tmp))
        except (OSError, subprocess.CalledProcessError) as e:
            print(f"the comparator (commit {rev}) cannot be read from git: {e}")
            return 1
        totals = {(who, r): [0.0, 0.0, 0] for who in ("before", "after") for r in ("peer", "own")}
        differ, skipped = 0, 0
        for k, (renderer, images, tip) in enumerate(seqs):
            order = [("before", old_cls), ("after", TipTracker)]
            if k % 2:
                order.reverse()
            try:  # a sequence whose first frame shows no tip that can be learnt is left out (both trackers)
                TipTracker(images[0], tip)
            except TemplateError:
                skipped += 1
                continue
            got = {}
            for who, cls in order:
                ans, wall, cpu = run(cls, images, tip)
                got[who] = ans
                tot = totals[(who, renderer)]
                tot[0] += wall
                tot[1] += cpu
                tot[2] += len(ans)
            differ += sum(a != b for a, b in zip(got["before"], got["after"], strict=True))
    print(f"the tracker at {rev} (before) and now (after), 512 x 512, one core, in turns")
    print(f"{'frames':>14} {'n':>5} {'wall/s before':>13} {'after':>7} {'ratio':>6} "
          f"{'CPU/s before':>12} {'after':>7} {'ratio':>6}")
    for r in ("peer", "own", "both"):
        rs = ("peer", "own") if r == "both" else (r,)
        b = [sum(totals[("before", x)][i] for x in rs) for i in range(3)]
        a = [sum(totals[("after", x)][i] for x in rs) for i in range(3)]
        fb, fa = b[2] / b[0], a[2] / a[0]
        cb, ca = b[2] / b[1], a[2] / a[1]
        print(f"{r + ' renderer' if r != 'both' else 'both':>14} {int(a[2]):>5} {fb:>13.1f} {fa:>7.1f} "
              f"{fa / fb:>6.2f} {cb:>12.1f} {ca:>7.1f} {ca / cb:>6.2f}")
    total = sum(v[2] for k, v in totals.items() if k[0] == "after")
    print(f"answers that differ between before and after: {differ} of {int(total)}")
    if skipped:
        print(f"sequences left out (no tip to learn in their first frame): {skipped}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
