"""The tracker's faster kernels against the plain numpy they replaced: equal bit for bit.

The speed-ups of :mod:`stickslip.vision` change no result (``benchmarks/golden_vision.py``
compares whole sequences); these check the kernels alone, cheaply, on inputs the
sequences rarely reach: patches cut by the frame's edge, an empty patch beyond it,
points outside the patch and far off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from stickslip.vision.refine import _ALL, _NO_GAIN_PLANE, _solve_positive_gain, _solve_small, _turned, steepest, warped
from stickslip.vision.sampling import Patch, _gradient, median, patch
from stickslip.vision.sampling import sample as _sample
from stickslip.vision.sampling import sample_value as _sample_value
from stickslip.vision.template import masked_ncc, region_spectra
from stickslip.vision.track import _downsample, _local_max, _peak_cells


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


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 30), nans=st.integers(0, 2), seed=st.integers(0, 2**32 - 1))
def test_median_is_numpys_bit_for_bit(n: int, nans: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.choice([-1.5, 0.0, 0.1, 2.0, 1e300], n) if seed % 2 else rng.normal(size=n)  # ties and extremes
    a[: min(nans, n)] = np.nan
    got, want = median(a), float(np.median(a))
    assert (math.isnan(got) and math.isnan(want)) or got == want
    assert math.isnan(median(np.zeros(0)))


@settings(max_examples=30, deadline=None)
@given(cx=st.floats(20.0, 60.0), cy=st.floats(15.0, 45.0), radius=st.floats(3.0, 14.0),
       seed=st.integers(0, 2**32 - 1))
def test_sampling_of_points_all_inside_the_patch_is_the_plain_one_bit_for_bit(cx: float, cy: float, radius: float,
                                                                             seed: int) -> None:
    # every point strictly inside: the clipping is skipped (sampling.cells), the values are the same
    rng = np.random.default_rng(seed)
    image = rng.normal(0.5, 0.1, (60, 80))
    p = patch(image, cx, cy, radius, 1.0)
    _, ch, cw = p.data.shape
    xs = p.x0 + rng.uniform(1e-9, cw - 1.000002, 300)
    ys = p.y0 + rng.uniform(1e-9, ch - 1.000002, 300)
    xs[:2] = (p.x0 + 1e-300, p.x0 + cw - 1.0000011)  # just inside the patch's first and last columns
    v, inside = _sample(p, xs, ys)
    v_old, inside_old = _sample_before(p, xs, ys)
    assert inside.all() and np.array_equal(v, v_old) and np.array_equal(inside, inside_old)
    none, none_inside = _sample(p, xs[:0], ys[:0])  # no point at all
    assert none.shape == (3, 0) and none_inside.shape == (0,)


def test_positive_contrast_is_judged_where_the_weights_are_not_zero() -> None:
    # a contrast plane below a fifth of its centre only where omega is 0 keeps the plane (the quick test of the
    # whole window fails, the subset's passes); below it where omega > 0: the plain contrast
    rng = np.random.default_rng(3)
    m = 200
    bx, by = np.linspace(-1.0, 1.0, m), np.zeros(m)
    D = np.asfortranarray(np.column_stack([np.ones(m), bx, by, np.ones(m), bx, by, rng.normal(size=(m, 4))]))
    y = D[:, :3] @ np.array([1.0, 0.9, 0.0]) + 0.01 * rng.normal(size=m)  # the gain 0.1 at bx = -1, 1.9 at +1
    omega = np.ones(m)
    omega[bx < -0.5] = 0.0  # the window's left quarter, where the gain falls from 0.55 to 0.1
    sol, gain, cols = _solve_positive_gain(D, omega, y, bx, by, None, 0.0, 0.0)
    assert cols is _ALL and sol is not None and gain is not None
    assert float(gain.min()) < 0.2 * sol[0] and bool((gain[omega > 0] > 0.2 * sol[0]).all())
    sol2, _, cols2 = _solve_positive_gain(D, np.ones(m), y, bx, by, None, 0.0, 0.0)
    assert cols2 is _NO_GAIN_PLANE and sol2 is not None and sol2[1] == 0.0 and sol2[2] == 0.0


def test_small_solve_is_numpys_and_refuses_a_singular_system() -> None:
    rng = np.random.default_rng(5)
    for _ in range(50):
        A = rng.normal(size=(40, 10))
        M, b = A.T @ A, rng.normal(size=10)
        got = _solve_small(M, b)
        assert got is not None and np.array_equal(got, np.linalg.solve(M, b))
    assert _solve_small(np.zeros((10, 10)), np.ones(10)) is None
    nan = _solve_small(np.full((3, 3), np.nan), np.ones(3))  # not singular to LAPACK: NaN, as numpy gives it
    assert nan is not None and np.isnan(nan).all()


@pytest.mark.parametrize("private", [None, "raises", "wrong shape"])
def test_small_solve_falls_back_to_numpys_when_the_private_solver_is_gone_or_changed(
    private: str | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`_solve_small` calls a private numpy gufunc: without it, or changed, the public solve answers."""
    from stickslip.vision import refine

    def changed(*args: object, **kw: object) -> object:
        if private == "raises":
            raise TypeError("solve1() got an unexpected keyword argument 'signature'")
        return np.zeros(3)

    monkeypatch.setattr(refine, "_SOLVE1", None if private is None else changed)
    A = np.random.default_rng(7).normal(size=(40, 10))
    M, b = A.T @ A, np.arange(10.0)
    got = _solve_small(M, b)
    assert got is not None and np.array_equal(got, np.linalg.solve(M, b))
    assert _solve_small(np.zeros((10, 10)), np.ones(10)) is None


@pytest.mark.parametrize("smooth", [1.0, 1.8027756377319946, 3.1622776601683795])
def test_patch_smooths_as_gaussian_filter(smooth: float) -> None:
    image = np.random.default_rng(2).normal(0.5, 0.1, (60, 80))
    p = patch(image, 30.3, 20.7, 15.0, smooth)
    h, w = p.data.shape[1:]
    crop = image[p.y0 : p.y0 + h, p.x0 : p.x0 + w]
    assert np.array_equal(p.data[0], ndimage.gaussian_filter(crop, smooth, mode="nearest"))


def test_turned_window_is_the_plain_rotation_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    t = ndimage.gaussian_filter(rng.normal(size=(21, 21)), 1.5)
    st_ = steepest(t, (10.3, 9.6), rng.uniform(0.0, 1.0, (21, 21)))
    image = rng.normal(size=(60, 60))
    for theta in (0.0, 0.13, -0.71, 3.0):
        ct, s_ = math.cos(theta), math.sin(theta)
        xs, ys = ct * st_.rx - s_ * st_.ry + 30.2, s_ * st_.rx + ct * st_.ry + 28.9
        xy = _turned(st_, 30.2, 28.9, theta)
        assert np.array_equal(xy[0], xs) and np.array_equal(xy[1], ys)
        p = patch(image, 30.2, 28.9, 20.0, 1.0)
        v, inside = warped(p, st_, 30.2, 28.9, theta)
        v_old, inside_old = _sample_before(p, xs, ys)
        assert np.array_equal(v, v_old[0]) and np.array_equal(inside, inside_old)


def test_correlation_is_the_plain_formula_bit_for_bit() -> None:
    from scipy import fft

    rng = np.random.default_rng(8)
    region = rng.normal(size=(37, 45))
    region[:, :12] = 1.0  # flat: the variance there is rounding noise, clipped at 0
    t, w = rng.normal(size=(9, 9)), rng.uniform(0.0, 1.0, (9, 9))
    got = masked_ncc(region, t, w)
    sw = float(w.sum())
    tc = t - float((w * t).sum() / sw)
    fw, fwt = fft.rfft2(w[::-1, ::-1], region.shape), fft.rfft2((w * tc)[::-1, ::-1], region.shape)
    fi, fi2 = fft.rfft2(region), fft.rfft2(region * region)
    a, b, c = (fft.irfft2(x, region.shape)[8:, 8:] for x in (fi * fw, fi2 * fw, fi * fwt))
    denom = np.sqrt(np.maximum(b - a * a / sw, 0.0) * float((w * tc * tc).sum()))
    out = np.where(denom > 1e-9 * denom.max(), c / np.where(denom > 0, denom, 1.0), 0.0)
    assert np.array_equal(got, np.clip(out, -1.0, 1.0))
    assert np.abs(got).max() <= 1.0 and np.abs(got[:, 8:]).min() > 0.0


def test_copies_with_the_same_weights_share_the_variance_and_give_their_own_correlation() -> None:
    rng = np.random.default_rng(9)
    region = rng.normal(size=(48, 48))
    w = rng.uniform(0.0, 1.0, (9, 9))
    spectra = region_spectra(region)
    cache: dict[object, object] = {}
    for k in range(3):  # as the whole-frame search compares its blur copies
        t = rng.normal(size=(9, 9))
        assert np.array_equal(masked_ncc(region, t, w, cache, ("coarse", k), spectra), masked_ncc(region, t, w))
    other = rng.uniform(0.0, 1.0, (9, 9))  # other weights: their own variance
    t = rng.normal(size=(9, 9))
    assert np.array_equal(masked_ncc(region, t, other, cache, ("coarse", 9), spectra), masked_ncc(region, t, other))


def test_shaft_sampling_is_the_plain_bilinear_one_bit_for_bit() -> None:
    from stickslip.vision.shaft import sample_frame

    rng = np.random.default_rng(6)
    image = rng.normal(0.5, 0.1, (50, 70))
    xs, ys = rng.uniform(-5.0, 75.0, 400), rng.uniform(-5.0, 55.0, 400)
    xs[:4], ys[:4] = (0.0, 69.0, 68.9999999, -0.0), (49.0, 0.0, 48.9999999, 12.5)  # on the frame's edges
    H, W = image.shape
    inside = (xs >= 0) & (xs <= W - 1) & (ys >= 0) & (ys <= H - 1)
    x, y = np.minimum(np.maximum(xs, 0.0), W - 1.000001), np.minimum(np.maximum(ys, 0.0), H - 1.000001)
    ix, iy = x.astype(np.intp), y.astype(np.intp)
    fx, fy, flat, i00 = x - ix, y - iy, image.reshape(-1), iy * W + ix
    top = flat[i00] + (flat[i00 + 1] - flat[i00]) * fx
    bottom = flat[i00 + W] + (flat[i00 + W + 1] - flat[i00 + W]) * fx
    v, got_inside = sample_frame(image, xs, ys)
    assert np.array_equal(v, top + (bottom - top) * fy) and np.array_equal(got_inside, inside)
    v2, inside2 = sample_frame(image, xs.reshape(20, 20), ys.reshape(20, 20))  # any shape, kept
    assert np.array_equal(v2, v.reshape(20, 20)) and np.array_equal(inside2, inside.reshape(20, 20))


@settings(max_examples=30, deadline=None)
@given(h=st.integers(1, 40), w=st.integers(1, 40), f=st.integers(1, 9), seed=st.integers(0, 2**32 - 1))
def test_downsample_is_numpys_block_mean_bit_for_bit(h: int, w: int, f: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 10.0 ** rng.integers(-3, 6), (h, w))
    a[rng.random((h, w)) < 0.2] = -0.0  # blocks of negative zeros keep their sign, as numpy's mean gives it
    got = _downsample(a, f)
    hh, ww = (h // f) * f, (w // f) * f
    want = a if f == 1 else a[:hh, :ww].reshape(h // f, f, w // f, f).mean(axis=(1, 3))
    assert got.shape == want.shape and np.array_equal(got, want)
    assert np.array_equal(np.signbit(got), np.signbit(want))


@settings(max_examples=30, deadline=None)
@given(h=st.integers(1, 30), w=st.integers(1, 30), r=st.integers(1, 3), seed=st.integers(0, 2**32 - 1))
def test_local_max_and_peaks_are_scipys_bit_for_bit(h: int, w: int, r: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.choice([-1.0, -0.0, 0.0, 0.3, 0.31, 0.5, 1.0], (h, w)) if seed % 2 else rng.uniform(-1.0, 1.0, (h, w))
    want = ndimage.maximum_filter(a, size=2 * r + 1)  # its default edges mirror the array
    assert np.array_equal(_local_max(a, r), want)
    ii, jj = np.nonzero((a == ndimage.maximum_filter(a, size=5)) & (a > 0.3))
    got_i, got_j = _peak_cells(a, 0.3)
    assert np.array_equal(got_i, ii) and np.array_equal(got_j, jj)


@settings(max_examples=30, deadline=None)
@given(m=st.integers(1, 12), q=st.integers(1, 30), n=st.integers(1, 9), seed=st.integers(0, 2**32 - 1))
def test_lines_mean_is_numpys_bit_for_bit(m: int, q: int, n: int, seed: int) -> None:
    from stickslip.vision.shaft import mean_lines

    rng = np.random.default_rng(seed)
    v = rng.normal(0.0, 10.0 ** rng.integers(-3, 6), (m, q, n))
    v[rng.random(v.shape) < 0.3] = -0.0  # lines of negative zeros keep their sign
    for a in (v, v[0]):
        got, want = mean_lines(a), a.mean(axis=-1)
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))


@pytest.mark.parametrize(("rows", "cols", "start"), [(105, 105, 40), (57, 57, 40), (128, 128, 9), (40, 48, 8),
                                                     (33, 16, 15), (16, 17, 0)])
def test_cropped_inverse_transform_is_scipys_bit_for_bit(rows: int, cols: int, start: int) -> None:
    from scipy import fft

    from stickslip.vision.template import _inverse

    rng = np.random.default_rng(rows * cols + start)
    alone = []
    for scale in (1e-3, 1.0, 1e4):  # a region's transform times a kernel's, as the correlation makes them
        spectrum = fft.rfft2(rng.normal(0.0, scale, (rows, cols))) * fft.rfft2(rng.normal(size=(9, 9)), (rows, cols))
        got = _inverse(spectrum, (rows, cols), start)
        assert np.array_equal(got, fft.irfft2(spectrum, (rows, cols))[start:, start:])
        alone.append((spectrum, got))
    stacked = _inverse(np.stack([s for s, _ in alone]), (rows, cols), start)  # several in one call: each alone's
    assert all(np.array_equal(stacked[i], got) for i, (_, got) in enumerate(alone))


@pytest.mark.parametrize("sigma", [0.5, 1.0, 1.8027756377319946, 3.0])
def test_profiles_smoothed_by_the_kept_kernel_as_gaussian_filter1d(sigma: float) -> None:
    from stickslip.vision.sampling import gaussian_weights

    rng = np.random.default_rng(int(sigma * 10))
    for shape in ((6, 81), (1, 5), (3, 1), (0, 9)):  # stations x samples; a profile shorter than the kernel; none
        a = rng.normal(0.5, 0.1, shape)
        got = ndimage.correlate1d(a, gaussian_weights(sigma), 1, mode="nearest")
        assert np.array_equal(got, ndimage.gaussian_filter1d(a, sigma, axis=1, mode="nearest"))


def test_edge_station_with_every_sample_in_the_frame_is_the_checked_one() -> None:
    from stickslip.vision.edges import SHIFTS, STEP, _profile, _station

    rng = np.random.default_rng(5)
    idx = np.arange(SHIFTS, 40 - SHIFTS)
    pr = _profile(np.tanh(np.linspace(-3.0, 3.0, idx.size)) + rng.normal(0.0, 0.05, idx.size), idx)
    assert pr is not None
    for _ in range(20):
        F = rng.normal(0.0, 1.0, 40)
        assert _station(pr, F, None) == _station(pr, F, np.ones(40, dtype=bool))
    F = np.zeros(40)
    F[idx - SHIFTS] = pr.e  # the template's profile SHIFTS samples before its place: the best shift is -SHIFTS
    every = _station(pr, F, None)
    assert every is not None and every[2] == -SHIFTS * STEP
    ok = np.ones(40, dtype=bool)
    ok[0] = False  # the shift -SHIFTS reaches outside the frame: not compared
    some = _station(pr, F, ok)
    assert some is not None and some[2] > -SHIFTS * STEP
    ok[:] = False
    assert _station(pr, F, ok) is None  # no shift in the frame


def _damped_before(dp: np.ndarray, prev_dp: np.ndarray | None) -> np.ndarray:
    """The step's damping as it was written before (both norms made at every step)."""
    if prev_dp is not None and float(dp @ prev_dp) < -0.5 * (math.sqrt(dp.dot(dp)) * math.sqrt(prev_dp.dot(prev_dp))):
        dp *= 0.5
    return dp


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12))
def test_damped_steps_with_the_norm_kept_are_the_plain_ones_bit_for_bit(seed: int, n: int) -> None:
    from stickslip.vision.refine import _damped

    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, 1.0, (n, 3)) * rng.choice([1e-6, 1.0, 30.0], (n, 1))
    steps[rng.random(n) < 0.2] = 0.0  # a step of nothing
    steps[1::2] = -rng.uniform(0.1, 3.0, (n // 2, 1)) * steps[0 : 2 * (n // 2) : 2]  # turning back: halved
    prev, prev_norm = None, None
    prev_old = None
    for s in steps:
        dp, prev_norm = _damped(s.copy(), prev, prev_norm)
        old = _damped_before(s.copy(), prev_old)
        assert np.array_equal(dp, old)
        if prev_norm is not None:
            assert prev_norm == math.sqrt(dp.dot(dp))
        prev, prev_old = dp, old



def test_needle_mask_grown_by_nothing_stays_the_mask() -> None:
    """``edge_px`` 0 and a sharp copy: the weights stay on the needle (scipy's dilation by 0 iterations would
    grow the mask to the whole window); by 2 px the weights reach exactly 2 px (8-neighbour-free cross steps)."""
    from stickslip.vision.template import TrackerParams, _grown, _level_weights

    mask = np.zeros((41, 41), dtype=bool)
    mask[20, 10:21] = True
    assert (_grown(mask, 0) == mask).all()
    assert int(_grown(mask, 2).sum()) == 11 * 5 + 2 * 3 + 2 * 1  # a 2-px cross-step dilation of a bar
    p = TrackerParams(edge_px=0, blur_bank=(0.0,), sharpen_bank=())
    (w,) = _level_weights(mask, np.ones_like(mask), (20.0, 20.0), p)
    far = ~_grown(mask, 3)
    assert float(w[far].max()) < 1e-3 < float(w[mask].min())


def test_a_negative_edge_growth_is_refused() -> None:
    """``edge_px`` below 0 would ask scipy for a dilation by 0 or fewer iterations (the whole window): refused."""
    from stickslip.vision.template import TrackerParams

    with pytest.raises(ValueError, match="edge_px = -1 px must be >= 0"):
        TrackerParams(edge_px=-1)
    assert TrackerParams(edge_px=0).edge_px == 0


def _needle_frame(size: int = 96, seed: int = 3) -> np.ndarray:
    """A dark needle pointing left, its tip at (50.3, 48.7), on a noisy ground."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    along, across = xx - 50.3, yy - 48.7
    needle = (along >= 0) & (np.abs(across) <= 2.0 + 0.2 * along)
    return ndimage.gaussian_filter(np.where(needle, 0.2, 0.8), 1.0) + rng.normal(0.0, 0.01, (size, size))


def test_blur_samples_share_cells_and_are_warpeds_bit_for_bit() -> None:
    """:func:`_blur_samples` (the patches of one place sharing their points' cells) against each blur's patch
    warped on its own: within the frame, cut by its edge, beyond it (an empty patch), and with a patch made
    elsewhere before (a group of its own)."""
    from stickslip.vision.track import TipTracker, _blur_samples, _frame_stats

    image = _needle_frame()
    tr = TipTracker(image, (50.3, 48.7))
    for x, y, theta, early in ((50.3, 48.7, 0.0, None), (51.1, 47.9, 0.12, (49.0, 50.0)), (3.2, 90.4, -0.3, None),
                               (-60.0, 40.0, 0.05, None), (94.6, 1.2, 0.0, (50.0, 48.0))):
        mine: dict[float, Patch] = {}
        plain: dict[float, Patch] = {}
        if early is not None:  # the sharp frame's patch made around the fit's start, as _try makes it
            mine[0.0] = plain[0.0] = tr._patch({}, image, early[0], early[1], 0.0)
        got = _blur_samples(tr, mine, image, x, y, theta)
        assert sorted(got) == sorted({f for _, f, _ in tr._spec})
        for f, (w, stats, all_in) in got.items():
            v, inside = warped(tr._patch(plain, image, x, y, f), tr._select, x, y, theta)
            w0 = tr._select.w * inside
            s0 = _frame_stats(v, w0)
            assert np.array_equal(w, w0) and all_in == bool(inside.all())
            assert stats[0] == s0[0] and np.array_equal(stats[1], s0[1]) and stats[2] == s0[2]


def _front_share_before(t: object, cand: object, blur: float) -> float:
    """The share in front of the tip as it was written before (the offsets gathered at every call)."""
    from stickslip.vision.sampling import sample_value

    r = cand.ref  # type: ignore[attr-defined]
    core, ring, (fx, fy) = t.core, t.ring, t.front  # type: ignore[attr-defined]
    if core[0].size < 3 or ring[0].size < 8:
        return 0.0
    far = np.hypot(fx, fy) >= 2.0 + 2.0 * blur
    ox = np.concatenate([core[0], ring[0], fx[far]])
    oy = np.concatenate([core[1], ring[1], fy[far]])
    ct, st_ = math.cos(r.theta), math.sin(r.theta)
    v, _ = sample_value(cand.patch, ct * ox - st_ * oy + r.x, st_ * ox + ct * oy + r.y)  # type: ignore[attr-defined]
    nc, nr = core[0].size, ring[0].size
    needle, ground = float(np.median(v[:nc])), float(np.median(v[nc : nc + nr]))
    if abs(needle - ground) < 1e-12:
        return 1.0
    if int(far.sum()) < 6:
        return 0.0
    return float(np.mean((v[nc + nr :] - ground) / (needle - ground) > 0.5))


def test_front_share_with_kept_offsets_is_the_plain_one() -> None:
    """:func:`_front_share` with its offsets kept (made again when the template's are) against the plain one: fits
    on the tip, off it, near and beyond the frame's edge, every blur; a flat frame (needle and ground alike)."""
    from dataclasses import replace

    from stickslip.vision.track import TipTracker, _front_share

    image = _needle_frame()
    tr = TipTracker(image, (50.3, 48.7))
    t = tr.template
    cache: dict[object, object] = {}
    n = 0
    for x, y, theta in ((50.3, 48.7, 0.0), (52.0, 47.1, 0.15), (40.0, 48.7, -0.2), (2.5, 93.0, 0.0),
                        (-30.0, 10.0, 0.3)):
        cand = tr._try(image, 50.3, 48.7, 0.0, 0)
        cand = replace(cand, ref=replace(cand.ref, x=x, y=y, theta=theta), patch=patch(image, x, y, 40.0, 1.0))
        for blur in (0.0, 1.0, 2.5, 6.0):
            got, want = _front_share(t, cand, blur, cache), _front_share_before(t, cand, blur)
            assert got == want
            n += 0.0 < want < 1.0
    assert n > 0  # some fit reads a share between none and all
    flat = replace(cand, patch=patch(np.full((96, 96), 0.5), 50.3, 48.7, 40.0, 1.0),
                   ref=replace(cand.ref, x=50.3, y=48.7, theta=0.0))
    assert _front_share(t, flat, 0.0, cache) == _front_share_before(t, flat, 0.0) == 1.0
    t.core = (t.core[0].copy(), t.core[1] + 1.0)  # the template's core made again: the offsets too
    assert _front_share(t, cand, 1.0, cache) == _front_share_before(t, cand, 1.0)


@settings(max_examples=40, deadline=None)
@given(sizes=st.lists(st.integers(0, 60), min_size=0, max_size=4), seed=st.integers(0, 2**32 - 1))
def test_peaks_by_rank_are_the_sorted_tuples(sizes: list[int], seed: int) -> None:
    """:func:`_by_rank` against ``sorted(..., reverse=True)`` of the tuples the search sorted before: several
    copies, equal significances (the row, column and copy then decide), none at all."""
    from stickslip.vision.track import _by_rank

    rng = np.random.default_rng(seed)
    peaks, tuples = [], []
    for k, n in enumerate(sizes):
        cells = rng.choice(30 * 30, n, replace=False)
        z = rng.choice([0.0, 0.31, 0.5, 1.2], n) if seed % 2 else rng.uniform(0.0, 3.0, n)
        ii, jj = cells // 30, cells % 30
        peaks.append((z, ii.astype(np.intp), jj.astype(np.intp), np.full(n, k, dtype=np.intp)))
        tuples += list(zip(z.tolist(), ii.tolist(), jj.tolist(), [k] * n, strict=True))
    got = list(_by_rank(peaks))
    assert got == sorted(tuples, reverse=True)
    assert all(type(v) is int for t in got for v in t[1:])


@settings(max_examples=40, deadline=None)
@given(cx=st.floats(-20.0, 90.0) | st.floats(20.0, 50.0), cy=st.floats(-20.0, 80.0) | st.floats(20.0, 50.0),
       dx=st.floats(-12.0, 12.0), dy=st.floats(-12.0, 12.0), theta=st.floats(-3.2, 3.2), seed=st.integers(0, 2**32 - 1))
def test_fit_window_sampled_untested_inside_its_patch_is_the_tested_one_bit_for_bit(
        cx: float, cy: float, dx: float, dy: float, theta: float, seed: int) -> None:
    # the fit's sampling (refine._warped3) against the sampling that tests every point: a window well inside its
    # patch, reaching past it (the tip moved from the patch's centre), cut by the frame's edge, beyond it
    from stickslip.vision.refine import _warped3
    from stickslip.vision.sampling import sample_xy

    rng = np.random.default_rng(seed)
    t = ndimage.gaussian_filter(rng.normal(size=(15, 15)), 1.5)
    st_ = steepest(t, (7.2, 6.9), rng.uniform(0.0, 1.0, (15, 15)))
    image = rng.normal(0.5, 0.1, (70, 80))
    p = patch(image, cx, cy, 7.0 * math.sqrt(2.0) + 6.0, 1.0)
    got, inside = _warped3(p, st_, cx + dx, cy + dy, theta)
    want, want_inside = sample_xy(p, _turned(st_, cx + dx, cy + dy, theta))
    assert np.array_equal(got, want)
    assert bool(want_inside.all()) if inside is None else np.array_equal(inside, want_inside)
    if inside is None:  # told untested only where every point lies strictly inside the patch, within the frame
        _, ch, cw = p.data.shape
        xy = _turned(st_, cx + dx, cy + dy, theta) - np.array(((p.x0,), (p.y0,)))
        assert xy.min() > 0.0 and xy.max() < min(ch, cw) - 1.000001 and want_inside.all()


def test_fit_window_sampled_at_a_nan_tip_or_with_no_pixel_is_tested() -> None:
    from stickslip.vision.refine import _warped3
    from stickslip.vision.sampling import sample_xy

    rng = np.random.default_rng(12)
    t = ndimage.gaussian_filter(rng.normal(size=(15, 15)), 1.5)
    st_ = steepest(t, (7.0, 7.0), rng.uniform(0.0, 1.0, (15, 15)))
    p = patch(rng.normal(size=(60, 60)), 30.0, 30.0, 16.0, 1.0)
    # a NaN tip is not told inside: it goes the tested way, which has no cell for it (the fit stops before)
    with np.errstate(invalid="ignore"), pytest.raises(IndexError):
        _warped3(p, st_, math.nan, 30.0, 0.1)
    with np.errstate(invalid="ignore"), pytest.raises(IndexError):
        sample_xy(p, _turned(st_, math.nan, 30.0, 0.1))
    none = steepest(t, (7.0, 7.0), np.zeros((15, 15)))  # no weighted pixel
    v0, inside0 = _warped3(p, none, 30.0, 30.0, 0.0)
    assert v0.shape == (3, 0) and (inside0 is None or inside0.shape == (0,))


def _joint_before(D: np.ndarray, w: np.ndarray, y: np.ndarray, cols: np.ndarray, kappa: float, turn: float
                  ) -> np.ndarray | None:
    """refine._joint as it was: the ridge added as a matrix, numpy's own solve."""
    Dc = D if cols is _ALL else D[:, cols]
    Dw = Dc * w[:, None]
    M = Dw.T @ Dc
    rhs = Dw.T @ y
    if kappa > 0:
        M[-1, -1] += kappa
        rhs[-1] += kappa * turn
    try:
        sol = np.linalg.solve(M + 1e-12 * M.trace() * np.eye(len(cols)), rhs)
    except np.linalg.LinAlgError:
        return None
    out = np.zeros(D.shape[1])
    out[cols] = sol
    return out


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(12, 300), kappa=st.sampled_from([0.0, 1e-3, 5.0]),
       plain=st.booleans(), held=st.booleans())
def test_joint_solve_with_the_ridge_in_place_is_the_plain_one_bit_for_bit(seed: int, m: int, kappa: float,
                                                                         plain: bool, held: bool) -> None:
    from stickslip.vision.refine import _joint

    rng = np.random.default_rng(seed)
    D = np.asfortranarray(rng.normal(size=(m, 10)) * rng.choice([1e-3, 1.0, 40.0], 10))
    w, y = rng.uniform(0.0, 1.0, m) * (rng.random(m) > 0.2), rng.normal(size=m)
    cols = _NO_GAIN_PLANE if plain else _ALL
    with np.errstate(invalid="ignore"):
        got = _joint(D, w, y, cols, kappa, 0.03, held)
    want = _joint_before(D, w, y, cols, kappa, 0.03)
    assert got is not None and want is not None and np.array_equal(got, want)
    # a singular system (a column of nothing, no ridge to hold it): None, as numpy's solve tells it
    D[:, 8] = 0.0
    with np.errstate(invalid="ignore"):
        assert (_joint(D, w, y, cols, 0.0, 0.0, held) is None) == (_joint_before(D, w, y, cols, 0.0, 0.0) is None)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), theta=st.floats(-1.0, 1.0), g=st.floats(0.2, 5.0),
       blur_c=st.floats(-2.0, 2.0))
def test_fit_jacobian_is_the_plain_formula_bit_for_bit(seed: int, theta: float, g: float, blur_c: float) -> None:
    from stickslip.vision.refine import _esm_jacobian

    rng = np.random.default_rng(seed)
    t = ndimage.gaussian_filter(rng.normal(size=(15, 15)), 1.5)
    st_ = steepest(t, (7.4, 6.6), rng.uniform(0.0, 1.0, (15, 15)))
    v3 = rng.normal(size=(3, st_.t.size)) * rng.choice([1e-4, 1.0, 300.0], (3, 1))
    ct, s_ = math.cos(theta), math.sin(theta)
    fgx = (v3[1] * ct + v3[2] * s_) / g
    fgy = (v3[2] * ct + v3[1] * -s_) / g
    fth = -fgx * st_.ry + fgy * st_.rx
    want = (blur_c * st_.sd_lap + st_.sd + np.stack((fgx, fgy, fth))) * 0.5
    assert np.array_equal(_esm_jacobian(st_, v3, theta, g, blur_c), want)


def test_fit_weights_kept_while_the_robust_ones_stay_are_the_plain_product() -> None:
    from stickslip.vision.refine import _weights

    rng = np.random.default_rng(13)
    w0, robust = rng.uniform(0.0, 1.0, 50), rng.uniform(0.0, 1.0, 50)
    robust[:5] = 0.0
    inside = rng.random(50) > 0.1
    omega, sw, kept = _weights(w0, inside, robust, None)  # a sample out of the frame: nothing kept
    assert kept is None and np.array_equal(omega, w0 * inside * robust) and sw == float((w0 * inside * robust).sum())
    omega, sw, kept = _weights(w0, None, robust, None)  # every sample in
    every = np.ones(50, dtype=bool)
    assert kept is not None and np.array_equal(omega, w0 * every * robust) and sw == float((w0 * every * robust).sum())
    again = _weights(w0, None, robust, kept)  # the same robust weights: the same arrays
    assert again[0] is omega and again[1] == sw
    other = robust.copy()  # new robust weights (equal or not): made again
    assert _weights(w0, None, other, kept)[0] is not omega


@settings(max_examples=30, deadline=None)
@given(cx=st.floats(-20.0, 90.0) | st.floats(20.0, 50.0), cy=st.floats(-20.0, 80.0) | st.floats(20.0, 50.0),
       dx=st.floats(-12.0, 12.0), dy=st.floats(-12.0, 12.0), theta=st.floats(-3.2, 3.2), seed=st.integers(0, 2**32 - 1))
def test_fit_window_cells_are_the_tested_ones_bit_for_bit(cx: float, cy: float, dx: float, dy: float, theta: float,
                                                         seed: int) -> None:
    # the cells the fit's score and the blur copies' comparison read (refine._window_cells) against sampling._corners
    from stickslip.vision.refine import _window_cells
    from stickslip.vision.sampling import _corners

    rng = np.random.default_rng(seed)
    t = ndimage.gaussian_filter(rng.normal(size=(15, 15)), 1.5)
    st_ = steepest(t, (6.8, 7.3), rng.uniform(0.0, 1.0, (15, 15)))
    p = patch(rng.normal(0.5, 0.1, (70, 80)), cx, cy, 7.0 * math.sqrt(2.0) + 6.0, 1.0)
    i00, fx, fy, inside = _window_cells(p, st_, cx + dx, cy + dy, theta)
    j00, gx, gy, want_inside = _corners(p, _turned(st_, cx + dx, cy + dy, theta))
    assert np.array_equal(i00, j00) and np.array_equal(fx, gx) and np.array_equal(fy, gy)
    assert bool(want_inside.all()) if inside is None else np.array_equal(inside, want_inside)


def test_fit_inverse_is_numpys_and_refuses_a_singular_matrix() -> None:
    from stickslip.vision.refine import _inverse

    rng = np.random.default_rng(14)
    for _ in range(30):
        A = rng.normal(size=(40, 10)) * rng.choice([1e-3, 1.0, 50.0], 10)
        M = A.T @ A
        got = _inverse(M)
        assert got is not None and np.array_equal(got, np.linalg.inv(M))
    assert _inverse(np.zeros((10, 10))) is None
    with np.errstate(invalid="ignore"):
        nan = _inverse(np.full((3, 3), np.nan))  # not singular to LAPACK: NaN, as numpy gives it
    assert nan is not None and np.isnan(nan).all()


@pytest.mark.parametrize(("cx", "cy"), [(30.3, 20.7), (2.0, 57.5), (-40.0, 10.0)])  # inside, cut by the edge, beyond
def test_patch_made_without_its_slopes_gets_the_same_ones_later(cx: float, cy: float) -> None:
    from stickslip.vision.refine import refine
    from stickslip.vision.sampling import with_slopes

    rng = np.random.default_rng(15)
    image = rng.normal(0.5, 0.1, (60, 80))
    full = patch(image, cx, cy, 15.0, 1.8027756377319946)
    bare = patch(image, cx, cy, 15.0, 1.8027756377319946, slopes=False)
    assert np.array_equal(bare.data[0], full.data[0]) and (not bare.slopes or bare.data.shape == (3, 4, 4))
    if not bare.slopes:
        assert np.isnan(bare.data[1:]).all()  # never read as slopes by mistake: NaN
        t = ndimage.gaussian_filter(rng.normal(size=(9, 9)), 1.5)
        with pytest.raises(ValueError, match="derivatives"):
            refine(bare, steepest(t, (4.0, 4.0), np.ones((9, 9))), (cx, cy))
    made = with_slopes(bare)
    assert made.slopes and np.array_equal(made.data, full.data) and (made.x0, made.y0) == (full.x0, full.y0)
    assert with_slopes(made) is made


def _spread(region: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The weighted spread of ``region`` under the window ``w`` at every offset, summed directly."""
    n = w.shape[0]
    out = np.zeros((region.shape[0] - n + 1, region.shape[1] - n + 1))
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            im = region[i : i + n, j : j + n]
            out[i, j] = math.sqrt((w * (im - (w * im).sum() / w.sum()) ** 2).sum())
    return out


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), level=st.sampled_from([0.0, 1.0, 1e3, -5e4]),
       rows=st.integers(12, 40), cols=st.integers(12, 40), cut=st.integers(0, 8))
def test_single_precision_correlation_is_doubles_to_a_few_millionths(seed: int, level: float, rows: int, cols: int,
                                                                     cut: int) -> None:
    """The tracker's correlations in single precision (the region less its level, complex64 transforms, the
    region's own padded to a quick size) against double precision's of the frame at level 0 (at a level of 5e4
    double precision's sums of squares lose more than single's about the mean), alone, with the region's spectra
    given (the whole-frame search's copies) and over the part inside the frame: within 2e-6 where the window's
    spread is at least a tenth of the largest, within 1e-6 (largest / spread)² elsewhere (a flat window: near 0)."""
    from stickslip.vision.template import inside_ncc

    rng = np.random.default_rng(seed)
    n = 9
    region = level + rng.normal(size=(rows, cols)) * rng.uniform(0.01, 10.0)
    region[: rows // 3, : cols // 3] = level  # flat: no correlation there
    t, w = rng.normal(size=(n, n)), rng.uniform(0.0, 1.0, (n, n))
    spread = _spread(region - level, w)
    bound = np.minimum(1e-6 * (spread.max() / np.maximum(spread, 1e-30)) ** 2, 2.0)
    bound[spread >= 0.1 * spread.max()] = 2e-6
    double = masked_ncc(region - level, t, w)
    single = masked_ncc(region, t, w, single=True)
    assert single.dtype == np.float64 and single.shape == double.shape
    assert np.all(np.abs(single - double) <= bound) and np.abs(single).max() <= 1.0
    cache: dict[object, object] = {}
    given_ = masked_ncc(region, t, w, cache, ("coarse", 0), region_spectra(region, single=True), single=True)
    assert np.all(np.abs(given_ - double) <= bound)  # the region's spectra at its own size
    inside = np.ones_like(region)
    inside[:, :cut] = 0.0  # the frame's left columns lie outside
    d, dc = inside_ncc((region - level) * inside, inside, t, w, least=0.3)
    s, sc = inside_ncc(region * inside, inside, t, w, least=0.3, single=True)
    assert np.array_equal(sc, dc)  # the share inside: double precision either way
    assert np.all(np.abs(s - d)[:, cut:] <= bound[:, cut:])  # the windows all inside; the others over fewer pixels
    assert np.abs(s).max() <= 1.0 and np.all(s[dc < 0.3] == 0.0) and np.all(d[dc < 0.3] == 0.0)  # too little in
    spectra = region_spectra(region * inside, inside, single=True)
    s2, _ = inside_ncc(region * inside, inside, t, w, {}, ("coarse", 0), spectra, 0.3, single=True)
    assert np.array_equal(s2, s)
