"""``stickslip serve``: the control room (a web page and an API that drive one manipulator).

The command parses its options, builds :class:`stickslip.server.room.RoomOptions` and
calls :func:`stickslip.server.run.serve`; the server (FastAPI, uvicorn) is the ``serve``
extra, imported only here.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl, urlsplit

import typer

from . import app
from ._common import (
    calibration_setting,
    database_setting,
    db_option,
    device_setting,
    err_console,
    fail,
    geometry_setting,
    max_age_setting,
    user_errors,
)

if TYPE_CHECKING:
    from ..audio.detector import Tuning

_EXTRA = ("fastapi", "uvicorn", "websockets")


def with_realtime(url: str) -> str:
    """A ``sim://`` URL with ``realtime=1`` added unless it says ``realtime=``; other URLs as they are.

    >>> with_realtime("sim://?seed=3")
    'sim://?seed=3&realtime=1'
    >>> with_realtime("sim://?realtime=0"), with_realtime("mm3a:///dev/ttyUSB0")
    ('sim://?realtime=0', 'mm3a:///dev/ttyUSB0')
    """
    parts = urlsplit(url)
    if parts.scheme not in ("sim", "sim+physics"):
        return url
    if any(k == "realtime" for k, _ in parse_qsl(parts.query, keep_blank_values=True)):
        return url
    return url + ("&" if parts.query else ("" if url.endswith("?") else "?")) + "realtime=1"


def _tunings(specs: list[str]) -> dict[int, Tuning]:
    """``--tuning J=FILE`` options to ``{joint: Tuning}``; one ``error:`` line for a bad one."""
    from ..audio.detector import Tuning

    out: dict[int, Tuning] = {}
    for spec in specs:
        joint_text, sep, path = spec.partition("=")
        if not sep or joint_text.strip() not in ("1", "2", "3") or not path.strip():
            fail(f"--tuning {spec}: write J=FILE, e.g. --tuning 3=tuning-joint3.json")
        joint = int(joint_text)
        with user_errors():
            tun = Tuning.load(Path(path.strip()))
        if tun.joint is not None and tun.joint != joint:
            fail(f"--tuning {spec}: {path} is tuned for joint {tun.joint}, not joint {joint}")
        out[joint] = tun
    return out


@app.command()
def serve(
    device: str | None = typer.Option(
        None, "--device", "-d",
        help="Controller URL (default: device in the config file, else the simulator in real time, "
        "sim://?realtime=1; a sim:// URL runs in real time unless it says realtime=0; &speed=10 runs it "
        "10 times faster). With --rig, the rig file names the controller.",
    ),
    rig_file: Path | None = typer.Option(
        None, "--rig", metavar="FILE",
        help="Rig file (TOML, docs/rig.md): serve one of its arms; every move, reach, jog, traverse and named "
        "position is checked against the rig's envelope before a step is sent, and the rig file's named "
        "positions join the saved ones.",
    ),
    arm: str | None = typer.Option(None, "--arm", help="The rig's arm to serve (default: its first arm)."),
    camera: str | None = typer.Option(
        None, "--camera", help="Camera URL for the camera panel: simcam://, opencv://0, files://frames/*.png "
        "(docs/vision.md)."
    ),
    camera_tip: str | None = typer.Option(
        None, "--camera-tip", metavar="X,Y",
        help="Where the tip is in the camera's first frame, px (x right, y down): the page then marks the "
        "tracked tip (stickslip camera locate finds it).",
    ),
    host: str = typer.Option(
        "127.0.0.1", "--host",
        help="Address to listen on. Loopback (the default) needs no token; any other address needs the "
        "token, made on first use and shown once.",
    ),
    port: int = typer.Option(8765, "--port", min=1, max=65535, help="TCP port."),
    calibration: Path | None = typer.Option(
        None, "--calibration", "-c",
        help="Calibration JSON (default: the config file's, else the latest stored for the device).",
    ),
    tuning: list[str] = typer.Option(  # noqa: B006 - typer's way to take a repeated option
        [], "--tuning", metavar="J=FILE",
        help="Limit-switch tuning of joint J (stickslip tune), for traverses and the calibration day; "
        "repeat per joint. The simulator tunes itself.", show_default=False,
    ),
    geometry: str | None = typer.Option(
        None, "--geometry", metavar="OFFSET,LENGTH",
        help="OFFSET,LENGTH of the arm, lengths with their units (as reach's --geometry; default: the config "
        "file's, else 0mm,21mm).",
    ),
    max_age: int | None = typer.Option(
        None, "--max-age", min=0, max=36500, metavar="<days>",
        help="Warn when the calibration is more than this many days old (default $STICKSLIP_MAX_AGE_DAYS, "
        "else max_age_days in the config file, else 0).",
    ),
    token_file: Path | None = typer.Option(
        None, "--token-file", help="Where the token is kept (default: serve-token in your configuration folder)."
    ),
    db: str | None = db_option(),
) -> None:
    """Serve a manipulator: a web page to drive it live, and an API for notebooks and scripts.

    One process owns the controller, the database and the calibration; the page (and
    stickslip.client.Rig from Python) jog, move, stop, save and return to positions and
    run the calibration day through the same procedures as the commands. Open the
    address it prints in a browser. STOP (the button, Esc or Space) stops every axis.

    Example: stickslip serve        (the simulator in real time, on http://127.0.0.1:8765/)

    Example: stickslip serve --rig lab.toml --arm left   (one arm of a rig; another
    server on another --port serves another arm)
    """
    missing = [m for m in _EXTRA if importlib.util.find_spec(m) is None]
    if missing:
        fail(f"stickslip serve needs the serve extra ({', '.join(missing)} missing): pip install 'stickslip[serve]'")
    from .rig import rig_arm

    ra = rig_arm(rig_file, arm, device, geometry, calibration, db)
    url = with_realtime(ra.device if ra is not None else device_setting(device).value)
    from ..devices.base import DeviceError, device_key
    from ..procedures.move import DeviceBusy
    from ..server.room import RoomOptions, serve_problem
    from ..server.run import ServeError
    from ..server.run import serve as run_server
    from ..storage import StoreError

    if ra is not None and (problem := serve_problem(ra.rig, ra.arm)) is not None:
        fail(problem)
    with user_errors():
        device_key(url)
    cal = ra.calibration if ra is not None else calibration_setting(calibration).value
    if cal is not None and not cal.exists():
        fail(f"--calibration: {cal} does not exist")
    options = RoomOptions(
        device=url, db=database_setting(ra.database if ra is not None else db).value, calibration=cal,
        tunings=_tunings(tuning),
        geometry=ra.geometry if ra is not None else geometry_setting(geometry).value,
        max_age_days=max_age_setting(max_age).value, rig=ra.rig if ra is not None else None,
        arm=ra.arm if ra is not None else None,
    )

    def echo(line: str) -> None:
        err_console.print(line, highlight=False, markup=False, soft_wrap=True)

    tip = None
    if camera_tip is not None:
        if camera is None:
            fail("--camera-tip needs --camera")
        try:
            x_text, y_text = camera_tip.split(",")
            tip = (float(x_text), float(y_text))
        except ValueError:
            fail(f"--camera-tip {camera_tip}: write X,Y in pixels, e.g. --camera-tip 310,242")
        if not all(math.isfinite(v) for v in tip):
            fail(f"--camera-tip {camera_tip}: the pixel position must be finite")
    with user_errors(ServeError, DeviceBusy, DeviceError, StoreError):
        run_server(options, host, port, camera_url=camera, camera_tip=tip, token_path=token_file, echo=echo)
