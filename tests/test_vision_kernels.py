"""The tracker's faster kernels against the plain numpy they replaced: equal bit for bit.

The speed-ups of :mod:`stickslip.vision` change no result (``benchmarks/golden_vision.py``
compares whole sequences); these check the kernels alone, cheaply, on inputs the
sequences rarely reach: patches cut by the frame's edge, an empty patch beyond it,
points outside the patch and far off.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.vision.refine import Patch, _gradient, _sample, _sample_value, patch
from stickslip.vision.template import masked_ncc, region_spectra


def _sample_before(p: Patch, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bilinear sampling as it was written before (four gathers, the frame tested for every point)."""
    H, W = p.shape
    _, ch, cw = p.data.shape
    lx, ly = xs - p.x0, ys - p.y0
    inside = (xs >= 0) & (xs <= W - 1) & (ys >= 0) & (ys <= H - 1)
    inside &= (lx >= 0) & (lx <= cw - 1) & (ly >= 0) & (ly <= ch - 1)
    lx = np.clip(lx, 0.0, cw - 1.000001)
    ly = np.clip(ly, 0.0, ch - 1.000001)
    ix, iy = lx.astype(np.intp), ly.astype(np.intp)
    fx, fy = lx - ix, ly - iy
    flat = p.data.reshape(3, -1)
    i00 = iy * cw + ix
    v00, v01 = np.take(flat, i00, axis=1), np.take(flat, i00 + 1, axis=1)
    v10, v11 = np.take(flat, i00 + cw, axis=1), np.take(flat, i00 + cw + 1, axis=1)
    top = v00 + (v01 - v00) * fx
    bottom = v10 + (v11 - v10) * fx
    return top + (bottom - top) * fy, inside


@settings(max_examples=40, deadline=None)
@given(h=st.integers(2, 12), w=st.integers(2, 12), seed=st.integers(0, 2**32 - 1))
def test_gradient_is_numpys_bit_for_bit(h: int, w: int, seed: int) -> None:
    a = np.random.default_rng(seed).normal(0.0, 100.0, (h, w))
    gx, gy = np.empty_like(a), np.empty_like(a)
    _gradient(a, gx, gy)
    ey, ex = np.gradient(a)
    assert np.array_equal(gx, ex) and np.array_equal(gy, ey)


@settings(max_examples=40, deadline=None)
@given(cx=st.floats(-30.0, 110.0), cy=st.floats(-30.0, 90.0), radius=st.floats(1.0, 30.0),
       smooth=st.sampled_from([0.0, 1.0, 1.8]), seed=st.integers(0, 2**32 - 1))
def test_sampling_is_the_plain_bilinear_one_bit_for_bit(cx: float, cy: float, radius: float, smooth: float,
                                                        seed: int) -> None:
    rng = np.random.default_rng(seed)
    image = rng.normal(0.5, 0.1, (60, 80))
    p = patch(image, cx, cy, radius, smooth)  # cut by the edge, or empty beyond it
    xs = rng.uniform(cx - radius - 5, cx + radius + 5, 200)
    ys = rng.uniform(cy - radius - 5, cy + radius + 5, 200)
    xs[:3] = (1e6, p.x0 + p.data.shape[2] - 1, -0.0)  # far off, the patch's last column, the frame's edge
    ys[:3] = (5.0, p.y0, 0.0)
    v, inside = _sample(p, xs, ys)
    v_old, inside_old = _sample_before(p, xs, ys)
    assert np.array_equal(v, v_old) and np.array_equal(inside, inside_old)
    v1, inside1 = _sample_value(p, xs, ys)
    assert np.array_equal(v1, v[0]) and np.array_equal(inside1, inside)


def test_spectra_given_or_made_give_the_same_correlation() -> None:
    rng = np.random.default_rng(3)
    region = rng.normal(size=(40, 40))
    t, w = rng.normal(size=(9, 9)), rng.uniform(0.0, 1.0, (9, 9))
    made = masked_ncc(region, t, w)
    given_ = masked_ncc(region, t, w, spectra=region_spectra(region))
    assert made.shape == (32, 32) and np.array_equal(made, given_)
    assert np.all(np.abs(made) <= 1.0)
