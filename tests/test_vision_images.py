"""Image files into frames: every format the issue names, and every bad input refused with one reason."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from stickslip.vision.camera import CameraEnded, CameraError, open_camera
from stickslip.vision.files import FileCamera, VideoCamera, frame_paths, open_frames
from stickslip.vision.frame import LUMINANCE, Frame, ImageError, as_image
from stickslip.vision.images import read_image, write_png

PIL = pytest.importorskip("PIL.Image")
tifffile = pytest.importorskip("tifffile")


def _ramp(h: int = 20, w: int = 30) -> np.ndarray:
    return np.add.outer(np.arange(h), np.arange(w)).astype(float) / (h + w)


def test_integers_scale_by_their_type_and_colour_takes_rec709_weights():
    assert as_image(np.full((16, 16), 255, np.uint8))[0, 0] == 1.0
    assert as_image(np.full((16, 16), 65535, np.uint16))[3, 3] == 1.0
    rgb = np.zeros((16, 16, 3), np.uint8)
    rgb[..., 1] = 255
    assert as_image(rgb)[0, 0] == pytest.approx(LUMINANCE[1], abs=1e-15)
    f = np.linspace(-1, 2, 16 * 16).reshape(16, 16)
    assert np.array_equal(as_image(f), f)  # floats kept as they are


@pytest.mark.parametrize(
    "data, words",
    [
        (np.zeros((5, 16, 16)), "stack of 5 images"),
        (np.zeros((8, 8)), "smaller than 16 x 16"),
        (np.zeros((16, 16, 2, 2)), "4-D"),
        (np.array([["a"] * 16] * 16), "are not grey"),
    ],
)
def test_what_is_not_one_grey_image_is_refused_with_the_reason(data, words):
    with pytest.raises(ImageError, match=words):
        as_image(data, "x.tif")


def test_nan_is_refused_naming_the_first_pixel():
    f = np.zeros((20, 30))
    f[7, 11] = np.nan
    f[9, 2] = np.inf
    with pytest.raises(ImageError, match=r"2 pixel\(s\).*x=11, y=7.*NaN"):
        as_image(f, "n.tif")


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("colour", [False, True])
@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_png_and_tiff_8_and_16_bit_grey_and_colour_read_exactly(tmp_path, dtype, colour, suffix):
    top = np.iinfo(dtype).max
    grey = np.round(_ramp() * top).astype(dtype)
    data = np.stack([grey, grey // 2, grey // 3], axis=-1) if colour else grey
    p = tmp_path / f"f{suffix}"
    if suffix == ".tif":
        tifffile.imwrite(p, data, photometric="rgb" if colour else "minisblack")
    elif colour and dtype == np.uint16:
        cv2 = pytest.importorskip("cv2")
        cv2.imwrite(str(p), data[..., ::-1])  # OpenCV writes BGR: the file holds RGB = data
    else:
        PIL.fromarray(data).save(p)
    img = read_image(p)
    g = grey.astype(float) / top
    want = g * LUMINANCE[0] + (grey // 2) / top * LUMINANCE[1] + (grey // 3) / top * LUMINANCE[2] if colour else g
    np.testing.assert_allclose(img, want, atol=1e-12)


def test_float_tiff_with_nan_is_refused_and_lzw_tiff_is_read(tmp_path):
    f = _ramp().astype(np.float32)
    f[4, 5] = np.nan
    tifffile.imwrite(tmp_path / "nan.tif", f)
    with pytest.raises(ImageError, match=r"nan.tif: 1 pixel\(s\).*x=5, y=4"):
        read_image(tmp_path / "nan.tif")
    grey = np.round(_ramp() * 65535).astype(np.uint16)
    # tifffile needs imagecodecs for LZW: Pillow reads it
    PIL.fromarray(grey).save(tmp_path / "lzw.tif", compression="tiff_lzw")
    np.testing.assert_allclose(read_image(tmp_path / "lzw.tif"), grey / 65535.0, atol=1e-12)


def test_a_tiff_stack_is_refused(tmp_path):
    tifffile.imwrite(tmp_path / "s.tif", np.zeros((3, 20, 30), np.uint16), photometric="minisblack")
    with pytest.raises(ImageError, match="stack of 3 images"):
        read_image(tmp_path / "s.tif")
    tifffile.imwrite(tmp_path / "v.tif", np.zeros((7, 20, 30), np.uint16), photometric="minisblack",
                     metadata={"axes": "ZYX"}, imagej=True)  # an ImageJ hyperstack: one series
    with pytest.raises(ImageError, match="stack of 7 images"):
        read_image(tmp_path / "v.tif")


def test_corrupt_truncated_empty_and_missing_files_are_refused(tmp_path):
    good = tmp_path / "g.png"
    PIL.fromarray(np.round(_ramp(64, 64) * 255).astype(np.uint8)).save(good)
    raw = good.read_bytes()
    (tmp_path / "t.png").write_bytes(raw[: len(raw) // 2])
    (tmp_path / "c.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 20)
    (tmp_path / "e.png").write_bytes(b"")
    for name, words in (("t.png", "not a readable image"), ("c.png", "not a readable image"),
                        ("e.png", "the file is empty"), ("missing.png", "no such file")):
        with pytest.raises(ImageError, match=words):
            read_image(tmp_path / name)
    with pytest.raises(ImageError, match="is a folder"):
        read_image(tmp_path)


def test_folders_globs_and_sequences(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ImageError, match="the folder has no image files"):
        frame_paths([tmp_path / "empty"])
    with pytest.raises(ImageError, match="no file matches"):
        frame_paths([str(tmp_path / "*.png")])
    for k, shape in enumerate([(20, 30), (20, 30), (24, 30)]):
        PIL.fromarray(np.zeros(shape, np.uint8)).save(tmp_path / f"f{k}.png")
    cam = FileCamera(frame_paths([tmp_path]), fps=10.0, pixel_size_m=0.5e-6)
    a, b = cam.grab(), cam.grab()
    assert (a.time_s, b.time_s, b.pixel_size_m) == (0.0, 0.1, 0.5e-6)
    with pytest.raises(ImageError, match=r"f2.png: 30 x 24 pixels, but the frames before it are 30 x 20"):
        cam.grab()
    with pytest.raises(CameraEnded):
        cam.grab()


def test_a_glob_in_a_folder_named_with_brackets_takes_the_folder_as_written(tmp_path):
    """'Messungen [2026]/*.png' matched nothing: the folder's '[2026]' was read as a character class."""
    folder = tmp_path / "Lab #1 100% [2026]" / "run [a]"
    folder.mkdir(parents=True)
    for name in ("f2.png", "f10.png"):
        PIL.fromarray(np.zeros((4, 4), np.uint8)).save(folder / name)
    (folder / "notes.txt").write_text("x")
    assert [p.name for p in frame_paths([str(folder / "*.png")])] == ["f2.png", "f10.png"]
    assert [p.name for p in frame_paths([str(folder / "f1[0-9].png")])] == ["f10.png"]
    assert [p.name for p in open_camera(f"files://{folder}/*.png").paths] == ["f2.png", "f10.png"]
    (tmp_path / "b").mkdir()  # a class where no folder is named so is still a class
    PIL.fromarray(np.zeros((4, 4), np.uint8)).save(tmp_path / "b" / "g.png")
    assert [p.parent.name for p in frame_paths([str(tmp_path / "[ab]" / "*.png")])] == ["b"]
    with pytest.raises(ImageError, match=r"run \[a\]/\*\.jpg: no file matches the pattern"):
        frame_paths([str(folder / "*.jpg")])


def test_a_files_url_whose_folder_name_holds_a_comma_is_taken_whole(tmp_path):
    """files://Messungen 1,2/*.png was split at the comma: 'Messungen 1: no such file'."""
    folder = tmp_path / "Messungen 1,2"
    folder.mkdir()
    for name in ("a.png", "b.png"):
        PIL.fromarray(np.zeros((4, 4), np.uint8)).save(folder / name)
    for location in (str(folder), f"{folder}/*.png", f"{folder}/a.png"):
        assert [p.name for p in open_camera(f"files://{location}").paths][0] == "a.png", location
    for name in ("c.png", "d.png"):
        PIL.fromarray(np.zeros((4, 4), np.uint8)).save(tmp_path / name)
    joined = open_camera(f"files://{tmp_path}/d.png,{tmp_path}/c.png").paths  # a comma still joins names
    assert [p.name for p in joined] == ["d.png", "c.png"]


def test_camera_urls(tmp_path):
    PIL.fromarray(np.zeros((20, 30), np.uint8)).save(tmp_path / "a.png")
    cam = open_camera(f"files://{tmp_path}?fps=5&pixel=0.25um")
    assert cam.info.pixel_size_m == pytest.approx(0.25e-6) and cam.grab().shape == (20, 30)
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['zoom'\]"):
        open_camera(f"files://{tmp_path}?zoom=2")
    with pytest.raises(ValueError, match=r"gives the option 'pixel' twice"):  # 0.25 or 2 um a pixel?
        open_camera(f"files://{tmp_path}?pixel=0.25um&fps=5&pixel=2um")
    with pytest.raises(ValueError, match=r"must be a size in \[1 pm, 1 cm\)"):  # was taken: 1e306 px per m
        open_camera(f"files://{tmp_path}?pixel=1e-300um")
    assert open_camera(f"files://{tmp_path}?pixel=1pm").info.pixel_size_m == pytest.approx(1e-12)
    with pytest.raises(ImageError, match=r"pixel size 1e-20 m must be in \[1 pm, 1 cm\)"):
        Frame(np.zeros((20, 30)), 0.0, 1e-20)
    with pytest.raises(ValueError, match="has no scheme"):
        open_camera(str(tmp_path))
    with pytest.raises(CameraError, match="unknown camera URL scheme 'usb'"):
        open_camera("usb://0?password=hunter2")
    with pytest.raises(CameraError) as e:
        open_camera("simcam://?password=hunter2")
    assert "hunter2" not in str(e.value) and "-d sim://" in str(e.value)


def test_video_round_trip_and_a_missing_opencv(tmp_path, monkeypatch):
    cv2 = pytest.importorskip("cv2")
    p = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48), isColor=False)
    for k in range(5):
        w.write(np.full((48, 64), 40 * k, np.uint8))
    w.release()
    cam = open_frames([p])
    assert isinstance(cam, VideoCamera)
    frames = [cam.grab() for _ in range(5)]
    assert [round(float(f.image.mean()) * 255 / 40) for f in frames] == [0, 1, 2, 3, 4]
    assert frames[1].time_s == pytest.approx(0.1, abs=1e-6)
    with pytest.raises(CameraEnded):
        cam.grab()
    cam.close()
    (tmp_path / "bad.avi").write_bytes(b"RIFF" + b"\0" * 200)
    with pytest.raises(CameraError, match="not a readable video"):
        VideoCamera(tmp_path / "bad.avi")
    monkeypatch.setitem(sys.modules, "cv2", None)  # OpenCV missing
    with pytest.raises(CameraError, match=r"needs OpenCV, which is not installed: pip install 'stickslip\[opencv\]'"):
        open_camera("opencv://0")


def test_frames_write_and_read_back_16_bit(tmp_path):
    img = _ramp(32, 40)
    write_png(tmp_path / "o.png", img)
    np.testing.assert_allclose(read_image(tmp_path / "o.png"), img, atol=0.5 / 65535)
    assert Frame(img, 1.5, 1e-6).shape == (32, 40)
    with pytest.raises(ImageError, match="pixel size"):
        Frame(img, 0.0, 2.0)


_HEADS = [b"\x89PNG\r\n\x1a\n", b"II*\x00", b"MM\x00*", b"GIF89a", b"BM", b"\xff\xd8\xff"]
FUZZ = settings(max_examples=120, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(head=st.sampled_from(_HEADS), body=st.binary(max_size=600), suffix=st.sampled_from([".png", ".tif", ".jpg"]))
@example(head=b"II*\x00", suffix=".tif",
         body=b"\x08\x00\x00\x00\x01\x00\x00\x01\x03\x00\x01\x00\x00\x00\xff\xff\x00\x00")
def test_fuzzed_files_give_an_image_or_one_image_error(tmp_path, head, body, suffix):
    """Random bytes behind an image format's signature: a grey finite image, or ImageError; nothing else."""
    p = tmp_path / f"fuzz{suffix}"
    p.write_bytes(head + body)
    try:
        img = read_image(p)
    except ImageError as e:
        assert str(e).startswith(str(p)) and "\n" not in str(e)
        return
    assert img.ndim == 2 and img.dtype == np.float64 and np.all(np.isfinite(img)) and min(img.shape) >= 16


@FUZZ
@given(cut=st.integers(1, 2000))
def test_truncated_real_files_never_pass_silently_wrong(tmp_path, cut):
    """A real PNG and TIFF cut anywhere: refused, or (if only trailing chunks are lost) the same image."""
    img = np.round(_ramp(40, 50) * 65535).astype(np.uint16)
    for name, save in (("c.png", lambda p: PIL.fromarray(img).save(p)), ("c.tif", lambda p: tifffile.imwrite(p, img))):
        p = tmp_path / name
        save(p)
        raw = p.read_bytes()
        p.write_bytes(raw[: max(0, len(raw) - cut)])
        try:
            got = read_image(p)
        except ImageError:
            continue
        assert np.array_equal(got, img / 65535.0), f"{name} cut by {cut} bytes read as another image"
    assert math.isfinite(cut)


def test_scikit_image_micrographs_read(tmp_path):
    """The real micrographs the peer renderer uses as backgrounds come through the loader (Pillow)."""
    sk = pytest.importorskip("skimage")
    folder = Path(sk.__file__).parent / "data"
    cell = read_image(folder / "cell.png")
    assert cell.shape == (660, 550) and 0.0 <= cell.min() < cell.max() <= 1.0


def test_frames_numbered_without_leading_zeros_are_taken_in_number_order(tmp_path):
    """f1 ... f12 (a camera or script that does not pad): f2 before f10, from a folder and a glob (audit33: the
    name sort gave f1, f10, f11, f12, f2, ..., each frame tracked with another one's time)."""
    for k in range(1, 13):
        PIL.fromarray(np.full((20, 30), k, np.uint8)).save(tmp_path / f"f{k}.png")
    (tmp_path / "f07b.png").write_bytes((tmp_path / "f7.png").read_bytes())
    want = [f"f{k}.png" for k in range(1, 8)] + ["f07b.png"] + [f"f{k}.png" for k in range(8, 13)]
    assert [p.name for p in frame_paths([tmp_path])] == want
    assert [p.name for p in frame_paths([str(tmp_path / "f*.png")])] == want
    cam = FileCamera(frame_paths([tmp_path]), fps=10.0)
    seen = [round(float(cam.grab().image[0, 0]) * 255) for _ in range(3)]
    assert seen == [1, 2, 3]
    # zero-padded names keep their order; names equal as numbers fall back to their text
    for name in ("g001.png", "g01.png", "g002.png", "g010.png", "g1.png"):
        PIL.fromarray(np.zeros((20, 30), np.uint8)).save(tmp_path / name)
    assert [p.name for p in frame_paths([str(tmp_path / "g*.png")])] == [
        "g001.png", "g01.png", "g1.png", "g002.png", "g010.png"]
