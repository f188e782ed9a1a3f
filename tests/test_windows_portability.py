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


def _text_opens_without_encoding() -> list[str]:
    """Every call in src/ that opens a text file without naming its encoding, as 'file:line call'."""
    import ast
    from pathlib import Path

    def mode_of(call: ast.Call, at: int) -> object:
        for k in call.keywords:
            if k.arg == "mode":
                return k.value.value if isinstance(k.value, ast.Constant) else None
        if len(call.args) > at:
            a = call.args[at]
            return a.value if isinstance(a, ast.Constant) else None
        return "r"

    found = []
    root = Path(__file__).resolve().parents[1] / "src"
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            owner = f.value.id if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) else ""
            if name in ("read_text", "write_text"):
                mode: object = "r"
            elif name == "open" and (isinstance(f, ast.Name) or owner == "io"):
                mode = mode_of(node, 1)
            elif name == "fdopen" and owner == "os":
                mode = mode_of(node, 1)
            elif name == "open" and isinstance(f, ast.Attribute) and node.args and isinstance(
                node.args[0], ast.Constant
            ) and isinstance(node.args[0].value, str):  # Path(...).open("w")
                mode = node.args[0].value
            else:
                continue
            if isinstance(mode, str) and "b" in mode:
                continue
            if any(k.arg == "encoding" or k.arg is None for k in node.keywords):  # named, or passed on (**kwargs)
                continue
            found.append(f"{path.relative_to(root)}:{node.lineno} {ast.unparse(node)[:80]}")
    return found


def test_every_text_file_src_opens_names_its_encoding() -> None:
    """Windows' default text encoding is the ANSI code page (cp1252), not UTF-8: a file opened without
    encoding= reads 'µm' written elsewhere as 'Âµm' and cannot write 'σ' at all."""
    assert _text_opens_without_encoding() == []


def test_the_encoding_check_finds_an_unnamed_encoding(tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """The check above can fail: a module with ``open(p)`` and ``p.write_text(s)`` is reported, twice."""
    import ast

    tree = ast.parse("open(p)\np.write_text(s)\nopen(p, 'rb')\np.read_text(encoding='utf-8')\n")
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    src = tmp_path / "src"
    src.mkdir()
    (src / "bad.py").write_text(ast.unparse(tree), encoding="utf-8")
    fake = tmp_path / "tests" / "test_x.py"
    monkeypatch.setitem(globals(), "__file__", str(fake))
    assert len(calls) == 4
    assert [x.split(" ")[0] for x in _text_opens_without_encoding()] == ["bad.py:1", "bad.py:2"]
