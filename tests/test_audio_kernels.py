"""The audio detector's shared spectra against the levels computed anew: equal bit for bit.

A tuning runs its candidates over the same few sounds and measures parts of its recording
that begin where it begins; :class:`~stickslip.audio.features.spectra.FramePowers` computes
their frames' spectra once. Every level served from it must be the float the plain path
gives (a sound known again, a sound that begins a kept one, a sound a kept one begins), and
a detector fed a whole sound must fire and keep its evidence as without it.
"""

from __future__ import annotations

import numpy as np

from stickslip.audio.change import TemplateDetector
from stickslip.audio.features.spectra import FramePowers, SubbandLevels, subband_bins, subband_levels_db, window
from stickslip.audio.tuningfile import Tuning

SR, FRAME, HOP = 48_000, 512, 128
EDGES = [300.0 * 2 ** (k / 3) for k in range(19)]


def _sound(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = 0.02 * rng.standard_normal(n)
    x[:: SR // 1000] += 0.3  # clicks at 1 kHz
    return x


def test_levels_from_kept_powers_equal_the_levels_computed_anew() -> None:
    x = _sound(40_000, 1)
    powers = FramePowers()
    plain = subband_levels_db(x, SR, FRAME, HOP, EDGES)
    # the first call computes and keeps; the prefix, the same sound and a longer one are served from what is kept
    for y in (x[:30_000], x, x[:12_345], np.concatenate((x, _sound(9_000, 2))), x):
        assert np.array_equal(
            subband_levels_db(y, SR, FRAME, HOP, EDGES, powers), subband_levels_db(y, SR, FRAME, HOP, EDGES)
        )
    assert np.array_equal(subband_levels_db(x, SR, FRAME, HOP, EDGES, powers), plain)
    # other edges (another resolution) over the same kept spectra
    fine = [300.0 * 2 ** (k / 6) for k in range(37)]
    assert np.array_equal(
        subband_levels_db(x, SR, FRAME, HOP, fine, powers), subband_levels_db(x, SR, FRAME, HOP, fine)
    )
    # a sound that differs in one sample is not taken for a kept one
    z = x.copy()
    z[20_000] += 1e-3
    assert np.array_equal(
        subband_levels_db(z, SR, FRAME, HOP, EDGES, powers), subband_levels_db(z, SR, FRAME, HOP, EDGES)
    )
    assert not np.array_equal(subband_levels_db(z, SR, FRAME, HOP, EDGES), plain)


def test_kept_powers_are_bounded_in_bytes() -> None:
    powers = FramePowers(max_bytes=2_000_000)
    w, _ = window(FRAME)
    for seed in range(6):
        powers(_sound(48_000, seed), FRAME, HOP, w.astype(np.float32))
    kept = powers._kept
    assert 0 < len(kept) < 6 and sum(k[4].nbytes + k[5].nbytes for k in kept) <= 2_000_000


def test_subband_levels_of_powers_equal_those_of_frames() -> None:
    x = _sound(20_000, 3)
    w, scale = window(FRAME)
    levels = SubbandLevels(w, scale, subband_bins(EDGES, SR, FRAME))
    frames = np.lib.stride_tricks.sliding_window_view(x, FRAME)[::HOP]
    assert np.array_equal(levels.from_powers(levels.powers(x, HOP, FramePowers())), levels(frames))


def test_a_detector_fed_a_whole_sound_decides_the_same_with_shared_spectra() -> None:
    from stickslip.audio.tuning import tune
    from stickslip.sim.sound import render_traverse_recording

    x, sr = render_traverse_recording(1, 1000.0, 2.0, 3.5, seed=11)
    tu: Tuning = tune(x, sr, 2.0, joint=1, per_octave=3.0, self_check=False)
    powers = FramePowers()
    runs = []
    for shared in (None, powers, powers):
        det = TemplateDetector(tu)
        det.powers = shared
        det.evidence = []
        runs.append((det.feed(np.asarray(x)), np.asarray(det.evidence)))
    assert runs[0][0] and runs[0][0] == runs[1][0] == runs[2][0]
    assert np.array_equal(runs[0][1], runs[1][1], equal_nan=True) and np.array_equal(
        runs[0][1], runs[2][1], equal_nan=True
    )
