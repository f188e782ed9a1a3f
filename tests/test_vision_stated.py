"""What an image file states that the frames are not read with (EXIF orientation, a TIFF's pixel size):
``camera locate`` says so in one warning line instead of ignoring it without a word (audit35)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.sim.camera import SimCamSettings, SimScene

PIL = pytest.importorskip("PIL.Image")
TIP = (70.3, 80.6)


def _frame(k: int) -> np.ndarray:
    """A sharp bright-field needle, its tip moved (1.5, -0.8) px per frame ``k``, as 8-bit grey."""
    scene = SimScene(SimCamSettings(look="optical", width=160, height=160, photons=150.0, seed=k + 1,
                                    tip_radius_m=2e-6, taper=math.radians(8.0), pixel_size_m=0.5e-6))
    img = scene.render(np.array((TIP[0] + 1.5 * k, TIP[1] - 0.8 * k)), np.array([math.cos(0.5), math.sin(0.5)]), 0.5)
    return np.asarray(np.clip(img * 255, 0, 255), dtype=np.uint8)


def _locate(pattern: str) -> tuple[list[dict[str, object]], list[str]]:
    r = CliRunner().invoke(app, ["camera", "locate", pattern, "--tip", f"{TIP[0]},{TIP[1]}", "--json"])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout), r.stderr.splitlines()


def test_an_exif_orientation_gets_one_warning_line_naming_the_frame_and_the_answer_is_as_stored(tmp_path):
    plain, turned = tmp_path / "plain", tmp_path / "turned"
    plain.mkdir()
    turned.mkdir()
    for k in range(3):
        im = PIL.fromarray(_frame(k))
        im.save(plain / f"f{k}.jpg", quality=95)
        exif = PIL.Exif()
        if k >= 1:
            exif[0x0112] = 6  # a camera held sideways: a viewer shows it turned 90° clockwise
        im.save(turned / f"f{k}.jpg", quality=95, exif=exif)
    out_plain, err_plain = _locate(str(plain / "f*.jpg"))
    assert err_plain == []
    out, err = _locate(str(turned / "f*.jpg"))
    assert len(err) == 1, err  # once per sequence, though two frames state it
    assert err[0].startswith("warning: ") and "f1.jpg states orientation 6" in err[0] and "stored pixels" in err[0]
    # read as stored: the same answers as the untagged files, to the last digit
    assert [(o["x"], o["y"]) for o in out] == [(o["x"], o["y"]) for o in out_plain]
    assert abs(float(out[2]["x"]) - (TIP[0] + 3.0)) < 0.5 and abs(float(out[2]["y"]) - (TIP[1] - 1.6)) < 0.5


@pytest.mark.parametrize(("tags", "words"), [
    ({"resolution": (72, 72), "resolutionunit": 2}, "f0.tif states a pixel of 352.8 µm (TIFF resolution tags)"),
    ({"resolution": (20000, 10000), "resolutionunit": 3},
     "f0.tif states a pixel of 0.5 x 1 µm (not square: a frame's pixel size is one number) (TIFF resolution tags)"),
    ({"metadata": {"PhysicalSizeX": 0.25, "PhysicalSizeY": 0.25}},
     "f0.ome.tif states a pixel of 0.25 µm (OME metadata)"),
    ({"resolution": (1, 1), "resolutionunit": 1}, None),  # no unit: no size stated (tifffile's default)
])
def test_a_tiff_that_states_a_pixel_size_gets_one_line_saying_it_is_not_used(tmp_path, tags, words):
    tifffile = pytest.importorskip("tifffile")
    for k in range(3):
        ome = "metadata" in tags
        tifffile.imwrite(tmp_path / f"f{k}.{'ome.tif' if ome else 'tif'}", _frame(k), ome=ome or None, **tags)
    out, err = _locate(str(tmp_path / "f*.tif"))
    assert len(out) == 3 and all("x" in o for o in out)
    if words is None:
        assert err == []
        return
    assert len(err) == 1 and err[0].startswith("warning: ") and words in err[0], err
    assert "it is not used" in err[0] and "pixel=0.5um" in err[0]


def test_a_stated_pixel_size_is_not_reported_when_the_url_gives_one(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    from stickslip.vision.camera import open_camera

    tifffile.imwrite(tmp_path / "f0.tif", _frame(0), resolution=(72, 72), resolutionunit=2)
    cam = open_camera(f"files://{tmp_path}")
    assert cam.grab().pixel_size_m is None and cam.stated_pixel is not None  # type: ignore[attr-defined]
    assert cam.stated_pixel[1].pixel_m == pytest.approx((0.0254 / 72, 0.0254 / 72))  # type: ignore[attr-defined]
    cam = open_camera(f"files://{tmp_path}?pixel=0.5um")
    assert cam.grab().pixel_size_m == 0.5e-6 and cam.stated_pixel is None  # type: ignore[attr-defined]


def test_a_glob_takes_the_files_a_folder_takes(tmp_path):
    from stickslip.vision.files import frame_paths
    from stickslip.vision.frame import ImageError

    for k in range(2):
        PIL.fromarray(_frame(k)).save(tmp_path / f"f{k}.png")
    (tmp_path / "Thumbs.db").write_bytes(b"\xd0\xcf\x11\xe0 not an image")
    (tmp_path / "f1.png.txt").write_text("notes")
    frames = [tmp_path / "f0.png", tmp_path / "f1.png"]
    assert frame_paths([tmp_path]) == frames
    assert frame_paths([str(tmp_path / "*")]) == frames  # was [f0.png, f1.png, f1.png.txt, Thumbs.db]
    out, err = _locate(str(tmp_path / "*"))  # was: exit 2 naming Thumbs.db
    assert [o["frame"] for o in out] == [str(p) for p in frames] and err == []
    with pytest.raises(ImageError, match=r"matches 1 files \(Thumbs.db, ...\) but no image file"):
        frame_paths([str(tmp_path / "T*")])
    with pytest.raises(ImageError, match="Thumbs.db: not a readable image"):  # named on its own: read, refused
        from stickslip.vision.images import read_image

        read_image(frame_paths([tmp_path / "Thumbs.db"])[0])
