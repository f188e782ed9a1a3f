"""The own renderer's micrograph mode (``vision_own.micrograph_benchmark``, ``bench_vision.py --micrograph``): a
real micrograph as the ground behind the needle, every other draw as the plain own frames'."""

from __future__ import annotations

import numpy as np
import pytest
from vision_own import GROUND_CONTRAST, micrograph, micrograph_benchmark, own_sequence

pytest.importorskip("skimage")
pytest.importorskip("PIL.Image")


def test_the_micrograph_replaces_only_the_ground():
    """The same seed with and without the ground: the same tips, kinds and blurs; the frames differ by the ground
    (far from the needle, the plain frame's smooth texture against the micrograph's structure)."""
    src = micrograph("retina")
    assert src is not None and src.shape == (800, 800)
    plain = own_sequence(3001, 6, 128, width_px=12.0, look="optical", photons=80.0, event_rate=0.15)
    real = own_sequence(3001, 6, 128, width_px=12.0, look="optical", photons=80.0, event_rate=0.15, ground=src)
    assert [f.tip for f in real.frames] == [f.tip for f in plain.frames]
    assert [(f.kind, f.blur) for f in real.frames] == [(f.kind, f.blur) for f in plain.frames]
    assert not np.array_equal(real.frames[0].image, plain.frames[0].image)


def test_the_ground_is_a_crop_at_the_stated_contrast():
    """``_ground``: zero mean over the crop about 0.85 in bright field, ``GROUND_CONTRAST`` times a spread near 0.5
    (the micrograph's own spread over a crop varies), and the crop's corner the scene's substrate stream draws."""
    from vision_own import _ground

    src = micrograph("micro")
    assert src is not None and src.shape == (408, 408)  # 102 x 102 px zoomed 4 times
    g = _ground(src, (160, 160), "optical", np.random.default_rng([5, 7]))
    assert g.shape == (160, 160) and abs(float(g.mean()) - 0.85) < 1e-9
    assert 0.2 < float(np.std(g)) / GROUND_CONTRAST < 0.8
    again = _ground(src, (160, 160), "optical", np.random.default_rng([5, 7]))
    np.testing.assert_array_equal(g, again)


def test_the_benchmark_draws_tips_and_photons_per_sequence():
    """Seed 3 of the retina's set: bright field, tips 10-18 px, 50-120 photons; sequence 1 is track51's
    (tip 12.2 px, 74 photons)."""
    seqs = micrograph_benchmark("retina", 3, n_seq=2, per_sequence=3)
    assert [s.look for s in seqs] == ["optical", "optical"]
    assert all(10.0 <= s.width_px <= 18.0 and 50.0 <= s.photons <= 120.0 for s in seqs)
    assert round(seqs[1].width_px, 1) == 12.2 and round(seqs[1].photons) == 74
