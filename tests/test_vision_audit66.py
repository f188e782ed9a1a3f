"""audit66: image files from other tools (1-bit, palette, inverted-grey, CMYK TIFFs) read as the picture they hold."""

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


def test_a_1_bit_tiff_reads_black_and_white_as_a_viewer_shows_it(tmp_path: Path):
    """tifffile writes a bool array as MinIsWhite (True stored as 1 is black), Pillow as BlackIsZero: each file
    reads as Pillow shows it, 0 and 1 (before: 0 and 1/255, and tifffile's file inverted)."""
    mask = _gradient() > 128
    tifffile.imwrite(tmp_path / "tifffile.tif", mask)
    PIL.fromarray(mask).save(tmp_path / "pillow.tif")
    for name, want in (("tifffile.tif", ~mask), ("pillow.tif", mask)):
        with PIL.open(tmp_path / name) as im:
            shown = np.asarray(im.convert("L"), dtype=float) / 255.0
        assert np.array_equal(shown, want.astype(float)), name
        assert np.array_equal(read_image(tmp_path / name), shown), name


def _luminance(rgb: np.ndarray) -> np.ndarray:
    f = rgb.astype(float) / float(np.iinfo(rgb.dtype).max)
    return f[..., 0] * LUMINANCE[0] + f[..., 1] * LUMINANCE[1] + f[..., 2] * LUMINANCE[2]


def test_a_palette_tiff_reads_its_colours_not_its_indices(tmp_path: Path):
    """A palette TIFF's pixels are indices into its colour map: read raw they were the index / 255 (here a
    ramp of 0..7 / 255 for a picture that runs from white to dark), a picture no viewer shows."""
    index = (_gradient() // 32).astype(np.uint8)  # 0..7, left to right
    cmap = np.zeros((3, 256), np.uint16)
    cmap[:, :8] = (65535 - np.arange(8) * 8000)[None, :]  # index 0 white, darker to the right
    tifffile.imwrite(tmp_path / "p.tif", index, photometric="palette", colormap=cmap)
    want = cmap[0, index] / 65535.0
    assert np.allclose(read_image(tmp_path / "p.tif"), want, atol=1e-12)
    colours = np.dstack([_gradient(), 255 - _gradient(), _gradient() // 2])
    pal = PIL.fromarray(colours).convert("P", palette=PIL.Palette.ADAPTIVE, colors=16)
    pal.save(tmp_path / "pil.tif")
    shown = _luminance(np.asarray(pal.convert("RGB")))  # Pillow writes a colour c as c * 256 in the map, not c * 257
    assert np.allclose(read_image(tmp_path / "pil.tif"), shown, atol=1 / 255)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, bool])
def test_an_inverted_grey_tiff_reads_as_a_viewer_shows_it(tmp_path: Path, dtype: type):
    """PhotometricInterpretation 0 (MinIsWhite): 0 is white. Read raw, the picture was inverted."""
    raw = _gradient() > 128 if dtype is bool else (_gradient().astype(np.uint64) * np.iinfo(dtype).max // 255)
    raw = raw.astype(dtype)
    tifffile.imwrite(tmp_path / "w.tif", raw, photometric="miniswhite")
    got = read_image(tmp_path / "w.tif")
    want = 1.0 - (raw.astype(float) if dtype is bool else raw / float(np.iinfo(dtype).max))
    assert np.allclose(got, want, atol=1e-12)
    assert got[0, 0] == 1.0 and got[0, -1] == 0.0  # white on the left, where the file stores 0


def test_a_cmyk_tiff_reads_as_its_colours(tmp_path: Path):
    """A CMYK TIFF (print software's 'separated') has ink, not light: read as RGBA its ramp ran backwards."""
    rgb = np.dstack([_gradient()] * 3)
    PIL.fromarray(rgb).convert("CMYK").save(tmp_path / "c.tif")
    got = read_image(tmp_path / "c.tif")
    assert np.allclose(got, _gradient() / 255.0, atol=1e-12)


def test_camera_grab_refuses_a_frame_a_png_cannot_hold_instead_of_clipping_it(tmp_path: Path):
    """A float TIFF in counts (100..4007) was saved as a PNG all 65535, exit 0; a signed one lost its negatives."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    counts = 100.0 + 4000.0 * np.add.outer(np.arange(20), np.arange(24)) / 43.0
    tifffile.imwrite(tmp_path / "counts.tif", counts.astype(np.float32))
    tifffile.imwrite(tmp_path / "signed.tif", (counts - 2000).astype(np.int16))
    runner = CliRunner()
    for name, words in (("counts.tif", "run from 100 to 4007"), ("signed.tif", "run from -0.057985 to 0.06122")):
        out = tmp_path / f"{name}.png"
        r = runner.invoke(app, ["camera", "grab", "--camera", f"files://{tmp_path / name}", "-o", str(out)])
        assert r.exit_code == 2, r.output
        lines = r.output.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:") and words in r.output, r.output
        assert "nothing written" in r.output and not out.exists()


def test_locate_tracks_the_frames_it_checked_when_the_folder_changes_between_its_passes(tmp_path: Path):
    """camera locate reads every frame, then tracks them: it named the folder's files twice. A frame written
    into the folder meanwhile (a camera still saving) that sorts first was tracked as the first frame, the
    needle learnt at --tip in a frame nobody checked, and the last checked frame dropped with nothing said."""
    from stickslip.devices import open_device
    from stickslip.vision.camera import open_camera
    from stickslip.vision.images import write_png
    from stickslip.vision.locate import locate

    dev = open_device("sim://")
    cam = open_camera("simcam://?pixel=0.5um&seed=3", dev)
    folder = tmp_path / "run"
    folder.mkdir()
    for k in range(3):
        write_png(folder / f"f{k + 1}.png", cam.grab().image)
    late = cam.grab().image
    cam.close()
    dev.close()

    def progress(done: int, total: int) -> None:
        if total == 0 and done == 1:  # the first pass has read one frame: another appears, sorting first
            write_png(folder / "a0.png", np.zeros_like(late))

    found = locate([folder], (307.2, 256.0), progress=progress)
    assert [Path(f.frame).name for f in found] == ["f1.png", "f2.png", "f3.png"]
    assert all(f.fix is not None for f in found)


def test_a_glob_that_matches_only_folders_says_so(tmp_path: Path):
    """'run*' over folders run1, run2 said 'no file matches the pattern', as if nothing were there."""
    from stickslip.vision.files import frame_paths
    from stickslip.vision.frame import ImageError

    for name in ("run1", "run2"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "f1.png").write_bytes(b"")
    with pytest.raises(ImageError) as e:
        frame_paths([str(tmp_path / "run*")])
    text = str(e.value)
    assert "matches 2 folder(s)" in text and str(tmp_path / "run1") in text and "run*/*.png" in text, text
    assert len(frame_paths([str(tmp_path / "run*" / "*.png")])) == 2


def test_a_grey_tiff_with_extra_samples_reads_its_grey(tmp_path: Path):
    """A grey page with extra samples: planar grey + alpha was refused as 'a stack of 2 images'; contiguous grey
    with two more channels was read as RGB (0.787 where the grey is 0)."""
    grey = np.tile(np.arange(24, dtype=np.uint16) * 2000, (20, 1))
    full = np.full_like(grey, 65535)
    tifffile.imwrite(tmp_path / "planar.tif", np.stack([grey, full]), photometric="minisblack",
                     planarconfig="separate", extrasamples=["unassalpha"])
    tifffile.imwrite(tmp_path / "contig.tif", np.dstack([grey, full, full]), photometric="minisblack",
                     planarconfig="contig", extrasamples=["unspecified", "unspecified"])
    tifffile.imwrite(tmp_path / "rgb5.tif", np.dstack([grey, grey, grey, full, full]), photometric="rgb",
                     planarconfig="contig", extrasamples=["unspecified", "unspecified"])
    tifffile.imwrite(tmp_path / "rgbplanar.tif", np.stack([grey, grey, grey]), photometric="rgb",
                     planarconfig="separate")
    for name in ("planar.tif", "contig.tif", "rgb5.tif", "rgbplanar.tif"):
        assert np.allclose(read_image(tmp_path / name), grey / 65535.0, atol=1e-12), name
    tifffile.imwrite(tmp_path / "volume.tif", np.zeros((3, 20, 24), np.uint8), photometric="minisblack",
                     volumetric=True, tile=(16, 16))  # one page of 3 slices (ImageDepth): still a stack
    from stickslip.vision.frame import ImageError

    with pytest.raises(ImageError, match="stack of 3"):
        read_image(tmp_path / "volume.tif")


def test_a_video_without_frames_is_named_in_the_one_line(tmp_path: Path):
    """camera locate said 'error: the recording has no frames' (which?); grab '... has no more frames (after 0)'."""
    cv2 = pytest.importorskip("cv2")
    from typer.testing import CliRunner

    from stickslip.cli import app

    video = tmp_path / "empty run.avi"
    cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 64)).release()
    assert video.stat().st_size > 0
    runner = CliRunner()
    for args in (["camera", "locate", str(video), "--tip", "30,30"],
                 ["camera", "grab", "--camera", f"video://{video}", "-o", str(tmp_path / "g.png")]):
        r = runner.invoke(app, args)
        assert r.exit_code == 2, r.output
        lines = r.output.splitlines()
        assert len(lines) == 1 and str(video) in lines[0] and "has no frames" in lines[0], r.output
