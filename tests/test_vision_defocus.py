"""Defocus as geometric optics draws it: a uniform blur circle in the own renderer.

A bright-field objective images a point out of focus as a nearly uniform disc (its rim
softened by diffraction); an SEM's beam out of focus is closer to a Gaussian. The own
renderer draws either (``SimCamSettings(defocus="disc")``, :func:`stickslip.sim.camera.defocus_kernel`),
of the Gaussian's variance: a disc of radius ``R`` has the variance ``R² / 4`` along a line,
so ``R = 2 sigma``. The tracker's disc copies measured on it were not merged (docs/vision-log.md,
"Defocus as a disc", issue 30; branch track69).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage
from vision_own import own_sequence

from stickslip.sim.camera import SimCamSettings, SimScene, _convolved, defocus_kernel


def _axis_variance(k: np.ndarray) -> float:
    h = k.shape[0] // 2
    x = np.arange(-h, h + 1)
    return float((k.sum(axis=0) * x * x).sum())


@pytest.mark.parametrize("sigma, rim", [(1.5, 0.5), (3.0, 0.0), (3.0, 0.5), (8.0, 0.5)])
def test_the_blur_circle_has_the_gaussians_variance_and_a_flat_middle(sigma: float, rim: float) -> None:
    k = defocus_kernel(sigma, rim)
    assert k.sum() == pytest.approx(1.0, abs=1e-12)
    assert math.sqrt(_axis_variance(k)) == pytest.approx(sigma, rel=0.005)
    r = 2.0 * math.sqrt(sigma * sigma - rim * rim)
    h = k.shape[0] // 2
    yy, xx = np.mgrid[-h : h + 1, -h : h + 1]
    middle = k[np.hypot(xx, yy) <= r - 1.5 - 2 * rim]
    assert middle.max() / middle.min() < 1.02  # uniform inside the rim
    assert k[np.hypot(xx, yy) >= r + 0.75 + 3 * rim].max(initial=0.0) < 1e-3 * k.max()  # nothing beyond it


def test_the_disc_is_convolved_with_its_edges_mirrored_as_the_gaussian_filter_does() -> None:
    img = np.random.default_rng(3).random((40, 53))
    k = defocus_kernel(3.0, 0.5)
    np.testing.assert_allclose(_convolved(img, k), ndimage.convolve(img, k, mode="reflect"), atol=1e-12)


def test_the_disc_defocus_changes_the_needles_blur_and_no_draw() -> None:
    g = own_sequence(5, n=6, size=96)
    d = own_sequence(5, n=6, size=96, defocus="disc")
    assert [(f.tip, f.kind, f.blur) for f in g.frames] == [(f.tip, f.kind, f.blur) for f in d.frames]
    blurred = [i for i, f in enumerate(g.frames) if f.blur > 0.6]
    assert blurred  # the seed draws blurred frames
    assert all(not np.array_equal(g.frames[i].image, d.frames[i].image) for i in blurred)
    with pytest.raises(ValueError, match="defocus"):
        SimScene(SimCamSettings(defocus="box"))


def test_a_straight_edge_blurred_by_the_disc_stops_at_its_radius() -> None:
    # a wide needle lying along x, blurred by sigma 4 px: the disc (R = 7.7 px with the 0.5 px rim) has reached the
    # ground 9 px beyond the edge, the Gaussian of the same variance still covers 1.2 % there (1 - Phi(9 / 4))
    s = SimCamSettings(look="optical", width=96, height=96, tip_radius_m=10e-6, pixel_size_m=0.5e-6, photons=1e9,
                       taper=math.radians(1.0), debris=0)
    cover, _ = SimScene(s)._needle(np.array([10.0, 48.0]), np.array([1.0, 0.0]), 1.0)
    edge = int(np.argmax(cover[:, 60] > 0.5)) - 1  # the last row outside the needle's upper edge at x = 60
    disc = _convolved(cover, defocus_kernel(4.0, 0.5))
    gauss = ndimage.gaussian_filter(cover, 4.0, truncate=3.0)
    assert disc[edge - 9, 60] < 1e-3
    assert gauss[edge - 9, 60] == pytest.approx(0.012, abs=0.006)
    # both halve the coverage at the edge
    assert disc[edge, 60] == pytest.approx(gauss[edge, 60], abs=0.08)


def test_the_simcam_url_takes_the_defocus_shape() -> None:
    """``simcam://?defocus=disc`` renders with the blur circle; an unknown shape is refused with the choices."""
    from stickslip.devices import open_device
    from stickslip.sim.camera import open_url

    arm = open_device("sim://")
    assert open_url("simcam://?size=64x48", arm).settings.defocus == "gaussian"
    assert open_url("simcam://?size=64x48&defocus=Disc", arm).settings.defocus == "disc"
    with pytest.raises(ValueError, match=r"simcam:// defocus='pillbox': the blur's shape is one of gaussian, disc"):
        open_url("simcam://?defocus=pillbox", arm)
