"""The stepping-again release judges a latched piece at once as it would frame by frame (audio.change.release).

:meth:`StopRelease.scan` takes the medians of a piece's frames in one call once the stop's
own departure is known; :meth:`StopRelease.frame`, one frame at a time, is the reference.
The two must agree on every piece (the frame that re-arms, or none) and leave the same
window behind, on any tuning, piece lengths and levels.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.audio.change.release import StopRelease


def _tuned(bands: int, release_frames: int, rng: np.random.Generator) -> SimpleNamespace:
    return SimpleNamespace(
        signature_db=tuple(rng.normal(0.0, 6.0, bands)),
        spread_db=tuple(rng.uniform(0.5, 3.0, bands)),
        release_frames=release_frames,
        sample_rate=48_000,
        hop=int(rng.choice([512, 1024, 4096])),
    )


def _frame_by_frame(rel: StopRelease, v: np.ndarray, template: np.ndarray, held: bool) -> int | None:
    d = v - template
    for k in range(v.shape[0]):
        if rel.frame(d[k], v[k], held):
            return k
    return None


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    bands=st.integers(1, 14),
    release_frames=st.integers(1, 40),
    pieces=st.lists(st.integers(0, 60), min_size=1, max_size=8),
    held=st.booleans(),
)
def test_a_piece_judged_at_once_re_arms_where_frame_by_frame_does(
    seed: int, bands: int, release_frames: int, pieces: list[int], held: bool
) -> None:
    rng = np.random.default_rng(seed)
    tuned = _tuned(bands, release_frames, rng)
    at_once, reference = StopRelease(tuned), StopRelease(tuned)  # type: ignore[arg-type]
    template = rng.normal(-40.0, 5.0, bands)
    stop = np.asarray(tuned.signature_db)
    for n in pieces:
        # frames like the stop, like stepping (near the template), or silent, in runs
        kind = rng.integers(0, 3, n)
        v = template + np.where(kind[:, None] == 0, stop, np.where(kind[:, None] == 1, 0.0, -15.0))
        v = v + rng.normal(0.0, 1.5, (n, bands))
        got, want = at_once.scan(v, template, held), _frame_by_frame(reference, v, template, held)
        assert got == want
        assert at_once.latched_frames == reference.latched_frames
        assert at_once.window.count == reference.window.count
        rows, ref_rows = at_once.window.stepping_rows(), reference.window.stepping_rows()
        assert len(rows) == len(ref_rows) and all(np.array_equal(a, b) for a, b in zip(rows, ref_rows, strict=True))
        if got is not None:  # re-armed: the detector starts a new latch after the next fire
            at_once.reset()
            reference.reset()
