"""What a lab running stickslip on a Windows PC writes, checked here as pure strings (no Windows machine in CI).

A serial port on Windows is ``COM3``: ``mm3a:///COM3`` (three slashes, as ``mm3a:///dev/ttyUSB0`` is written)
reached pyserial as ``/COM3``, which Windows cannot open; ``anc300://COM3`` was dialled as the network host
``com3`` and ``anc300:///COM3`` opened ``/COM3``: the ANC300's serial console could not be named at all.
"""

from __future__ import annotations

from typing import Any

import pytest

from stickslip.devices import anc300, nanocontrol, smaract
from stickslip.devices.transport import serial_port_name


class Opened(Exception):
    """Raised by the stand-in transport: the port the driver would have opened."""


def _capture(monkeypatch: pytest.MonkeyPatch, module: Any) -> None:
    def fake(port: str, *args: Any, **kwargs: Any) -> None:
        raise Opened(port)

    monkeypatch.setattr(module, "SerialTransport", fake)
    monkeypatch.setattr(module, "SocketTransport", lambda host, *a, **k: (_ for _ in ()).throw(Opened("tcp:" + host)))


@pytest.mark.parametrize(
    ("path", "port"),
    [("/COM3", "COM3"), ("/com12", "com12"), ("COM3", "COM3"), ("/dev/ttyUSB0", "/dev/ttyUSB0"),
     ("/dev/COM3", "/dev/COM3"), ("/COM", "/COM"), ("", "")],
)
def test_serial_port_name_takes_a_windows_com_port_out_of_a_url_path(path: str, port: str) -> None:
    assert serial_port_name(path) == port


@pytest.mark.parametrize(
    ("module", "url", "port"),
    [
        (nanocontrol, "mm3a:///COM3", "COM3"),
        (nanocontrol, "mm3a://COM3", "COM3"),
        (nanocontrol, "mm3a:///dev/ttyUSB0", "/dev/ttyUSB0"),
        (smaract, "smaract-mcs:///COM4", "COM4"),
        (anc300, "anc300:///COM5", "COM5"),
        (anc300, "anc300://COM5", "COM5"),
        (anc300, "anc300:///dev/ttyUSB0", "/dev/ttyUSB0"),
        (anc300, "anc300://192.168.1.2", "tcp:192.168.1.2"),
        (anc300, "anc300://com3.lab.example", "tcp:com3.lab.example"),
    ],
)
def test_drivers_open_a_windows_com_port_named_in_their_url(
    monkeypatch: pytest.MonkeyPatch, module: Any, url: str, port: str
) -> None:
    _capture(monkeypatch, module)
    with pytest.raises(Opened) as e:
        (module.open_mcs if module is smaract else module.open_url)(url)
    assert str(e.value) == port


@pytest.mark.parametrize(
    ("location", "windows", "path"),
    [
        ("/C:/frames/*.png", True, "C:/frames/*.png"),  # files:///C:/frames/*.png, as file:/// URLs write a drive
        ("/d:\\frames\\*.png", True, "d:\\frames\\*.png"),
        ("C:\\frames\\*.png", True, "C:\\frames\\*.png"),  # files://C:\frames\*.png: as written
        ("frames/*.png", True, "frames/*.png"),
        ("/C:/frames", False, "/C:/frames"),  # a POSIX path is taken as written
        ("/data/frames", True, "/data/frames"),
    ],
)
def test_a_camera_url_location_names_a_windows_drive(location: str, windows: bool, path: str) -> None:
    from stickslip.vision.files import location_path

    assert location_path(location, windows=windows) == path


def test_a_camera_url_location_expands_the_home_folder(monkeypatch: pytest.MonkeyPatch, tmp_path: Any) -> None:
    """files://~/frames/*.png named a folder called '~' (no shell expands '~' inside a URL)."""
    from stickslip.vision.files import open_files_url
    from stickslip.vision.images import write_png

    np = pytest.importorskip("numpy")
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("USERPROFILE", str(tmp_path))
    (tmp_path / "frames").mkdir()
    for k in range(2):
        write_png(tmp_path / "frames" / f"f{k}.png", np.full((8, 8), 0.5))
    cam = open_files_url("files://~/frames/*.png?fps=2")
    assert len(cam) == 2
    cam.close()
