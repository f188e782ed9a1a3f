"""audit66: image files from other tools (1-bit, palette, inverted-grey and CMYK TIFFs) read as the picture they hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stickslip.vision.frame import LUMINANCE, as_image
from stickslip.vision.images import read_image

PIL = pytest.importorskip("PIL.Image")
tifffile = pytest.importorskip("tifffile")


def _gradient(h: int = 20, w: int = 24) -> np.ndarray:
    """A left-to-right grey ramp, 0..255 (uint8)."""
    return np.tile(np.linspace(0, 255, w).round().astype(np.uint8), (h, 1))


def test_booleans_become_0_and_1_as_the_docstring_says():
    mask = np.zeros((16, 16), bool)
    mask[4:9, 2:7] = True
    img = as_image(mask)
    assert img.max() == 1.0 and img.min() == 0.0  # before: 1/255
    assert np.array_equal(img, mask.astype(float))


def test_a_1_bit_tiff_reads_black_and_white(tmp_path: Path):
    mask = _gradient() > 128
    tifffile.imwrite(tmp_path / "tifffile.tif", mask)
    PIL.fromarray(mask).save(tmp_path / "pillow.tif")
    for name in ("tifffile.tif", "pillow.tif"):
        assert np.array_equal(read_image(tmp_path / name), mask.astype(float)), name
