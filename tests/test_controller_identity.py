"""The controller behind a URL is the one its positions were kept for (stickslip.devices.identity).

The realistic silent failure: two SmarAct MCS2s on a DHCP network swap addresses (or two USB
adapters swap ``/dev/ttyUSB0`` and ``/dev/ttyUSB1``), and the next ``move`` plans from the other
arm's kept position. Here the emulator keeps its URL and is given another serial number (system
id) between two moves: the second move must send nothing, refuse in one line, and leave every
joint uncertain over its whole range. The simulator tells its seed; a seed is part of a ``sim://``
key, so ``sim://?seed=3`` after ``sim://`` is another device, not a swap.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from server_support import room_on
from synth import paper_table
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.devices.base import open_device
from stickslip.devices.identity import IDENTITY_KEY, SWAPPED, ControllerChanged, kept_identity
from stickslip.devices.positions import load_state
from stickslip.measurements import measurements_to_csv
from stickslip.procedures.move import MoveRequest, move
from stickslip.server.slot import Conflict
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.smaract_emulator import MCS2Emulator, MCSEmulator
from stickslip.storage import Store

runner = CliRunner()


@pytest.fixture(scope="module")
def cal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("cal")
    (tmp / "meas.csv").write_text(measurements_to_csv(paper_table()))
    r = runner.invoke(app, ["calibrate", str(tmp / "meas.csv"), "-o", str(tmp / "cal.json")])
    assert r.exit_code == 0, r.output
    return tmp / "cal.json"


def _move(url: str, cal: Path, db: str, by: str = "200um") -> tuple[int, str]:
    r = runner.invoke(app, ["move", "-d", url, "-c", str(cal), "--joint", "3", "--by", by, "--q2", "-90deg",
                            "--trust-calibration", "--db", db])
    return r.exit_code, r.output


def _where(url: str, db: str) -> dict[str, object]:
    r = runner.invoke(app, ["where", "-d", url, "--db", db, "--offline", "--json"])
    assert r.exit_code == 0, r.output
    out: dict[str, object] = json.loads(r.stdout)
    return out


@pytest.mark.parametrize("emulator, attribute, first, other", [
    (MCS2Emulator, "serial_number", "MCS2 serial MCS2-00004711", "MCS2 serial MCS2-00009999"),
    (MCSEmulator, "system_id", "MCS system id 1234567890", "MCS system id 9999"),
])
def test_another_controller_at_the_same_url_is_refused_and_leaves_every_joint_uncertain(
    emulator: type, attribute: str, first: str, other: str, cal: Path, tmp_path: Path
) -> None:
    db = str(tmp_path / "s.db")
    with emulator(SimulatedMM3A(seed=4), transport="tcp") as emu:
        url = emu.url + "?hz=5000"
        assert runner.invoke(app, ["where", "-d", url, "--offline", "--set", "3=1mm", "--db", db]).exit_code == 0
        code, out = _move(url, cal, db)
        assert code == 0, out
        sent = dict(emu.steps)
        assert sent[2] != 0
        setattr(emu, attribute, other.rsplit(" ", 1)[1])  # another controller now answers at this URL
        code, out = _move(url, cal, db)
        assert code != 0
        line = " ".join(out.split())
        assert f"another controller answers at {emu.url}" in line, out
        assert f"{other}, where the positions were kept for {first}" in line and "nothing was sent" in line
        assert "re-reference" in line and "--set J=min" in line
        assert emu.steps == sent  # nothing was sent
        joints = _where(url, db)["joints"]
        assert isinstance(joints, list)
        for j in joints:
            spec = kin.JOINTS[j["joint"]]
            assert j["uncertain"] == [pytest.approx(spec.lower), pytest.approx(spec.upper)], j
        with Store.open(db) as store:
            assert set(load_state(store, emu.url).why.values()) == {SWAPPED}
            assert kept_identity(store, emu.url) == other  # the new one is kept
        code, out = _move(url, cal, db)  # the next move is refused by the uncertainty, still nothing sent
        assert code != 0 and "uncertain" in out and SWAPPED in " ".join(out.split())
        assert emu.steps == sent
        assert runner.invoke(app, ["where", "-d", url, "--offline", "--set", "3=1mm", "--db", db]).exit_code == 0
        code, out = _move(url, cal, db)  # re-referenced: the new controller is the kept one, the move runs
        assert code == 0, out
        assert emu.steps[2] != sent[2]


def _sim_cal() -> object:
    from stickslip.calibration import Calibration

    sim = SimulatedMM3A(seed=0)
    models = sim.true_models()
    return Calibration(models=models, stderr=dict.fromkeys(models), constant_steps=dict.fromkeys(models, 1e-6),
                       day="2026-11-22", method="paper")


def test_the_simulator_tells_its_seed_and_another_seed_under_one_key_is_a_swap(tmp_path: Path) -> None:
    cal = _sim_cal()
    with Store.open(tmp_path / "s.db") as store:
        req = MoveRequest("sim://", 3, by=1e-4, trust_calibration=True)
        move(store, req, cal)  # type: ignore[arg-type]
        assert kept_identity(store, "sim://") == "simulator seed 0"
        before = load_state(store, "sim://").positions[3]
        with pytest.raises(ControllerChanged, match="simulator seed 5, where the positions were kept for simulator"):
            move(store, req, cal, opener=lambda _url: SimulatedMM3A(seed=5))  # type: ignore[arg-type]
        st = load_state(store, "sim://")
        assert st.positions[3] == before
        assert st.uncertain == {j: (kin.JOINTS[j].lower, kin.JOINTS[j].upper) for j in (1, 2, 3)}
        assert set(st.why.values()) == {SWAPPED}
        assert kept_identity(store, "sim://") == "simulator seed 5"


def test_another_seed_is_another_device_not_a_swap(tmp_path: Path) -> None:
    cal = _sim_cal()
    with Store.open(tmp_path / "s.db") as store:
        move(store, MoveRequest("sim://", 3, by=1e-4, trust_calibration=True), cal)  # type: ignore[arg-type]
        r = move(store, MoveRequest("sim://?seed=3", 3, by=1e-4, trust_calibration=True), cal)  # type: ignore[arg-type]
        assert r.outcome.error is None and r.outcome.sent != 0
        assert kept_identity(store, "sim://?seed=3") == "simulator seed 3"
        assert kept_identity(store, "sim://") == "simulator seed 0"
        assert load_state(store, "sim://").uncertain == {} and load_state(store, "sim://?seed=3").uncertain == {}


def test_a_store_written_before_identities_were_kept_is_a_first_opening(tmp_path: Path) -> None:
    cal = _sim_cal()
    with Store.open(tmp_path / "s.db") as store:
        store.set_state("sim://", "positions", {"version": 1, "positions": {"1": 0.0, "2": -1.5, "3": 0.004},
                                                "sources": {"1": "set", "2": "set", "3": "set"}})
        assert store.get_state("sim://", IDENTITY_KEY) is None
        seen: list[str] = []
        r = move(store, MoveRequest("sim://", 3, by=1e-4, trust_calibration=True), cal,  # type: ignore[arg-type]
                 warn=seen.append)
        assert r.outcome.error is None and r.outcome.sent > 0
        assert not [w for w in seen if "controller" in w]
        assert kept_identity(store, "sim://") == "simulator seed 0"
        assert load_state(store, "sim://").uncertain == {}


def test_a_controller_that_cannot_tell_is_not_compared(tmp_path: Path) -> None:
    """An ANC300 or a NanoControl tells no identity: nothing kept, nothing refused."""
    from stickslip.devices.base import DeviceInfo

    class Silent(SimulatedMM3A):
        @property
        def info(self) -> DeviceInfo:
            base = super().info
            return DeviceInfo(base.url, "silent", base.joints, base.extra)

    cal = _sim_cal()
    with Store.open(tmp_path / "s.db") as store:
        req = MoveRequest("sim://", 3, by=1e-4, trust_calibration=True)
        move(store, req, cal, opener=lambda _url: Silent(seed=0))  # type: ignore[arg-type]
        move(store, req, cal, opener=lambda _url: Silent(seed=5))  # type: ignore[arg-type]
        assert store.get_state("sim://", IDENTITY_KEY) is None


def test_the_server_refuses_a_move_on_another_controller(tmp_path: Path) -> None:
    url = "sim://"
    first = room_on(tmp_path, url)
    try:
        m = first.move(3, 1e-4, None)
        m.finished.wait(20)
        assert m.status == "done", m.error
    finally:
        first.close()
    cal_path = tmp_path / "true-cal.json"
    from stickslip.server.room import ControlRoom, RoomOptions

    room = ControlRoom(RoomOptions(device=url, db=tmp_path / "serve.db", calibration=cal_path),
                       opener=lambda _url: open_device("sim://?seed=6"))
    try:
        with pytest.raises(Conflict, match="another controller answers at sim://: simulator seed 6, where the "
                                           "positions were kept for simulator seed 0; nothing was sent") as e:
            room.move(3, 1e-4, None)
        assert e.value.status == 409
        dev = room.owned.dev
        assert isinstance(dev, SimulatedMM3A) and dev.steps_simulated == 0
        joints = room.where()["joints"]
        assert [j["uncertain"] for j in joints] == [
            [pytest.approx(kin.JOINTS[j].lower), pytest.approx(kin.JOINTS[j].upper)] for j in (1, 2, 3)]
        with pytest.raises(Conflict, match=SWAPPED):  # the next move: the joints are uncertain
            room.move(3, 1e-4, None)
        assert dev.steps_simulated == 0
    finally:
        room.close()


@pytest.mark.parametrize("url, warned", [
    ("mm3a:///dev/ttyUSB0", True), ("anc300:///dev/ttyACM1?password=x", True),
    ("mm3a:///dev/serial/by-id/usb-FTDI_FT232R_A1B2C3-if00-port0", False), ("mm3a://COM3", False),
    ("anc300://192.168.1.2", False), ("sim://", False),
])
def test_where_suggests_the_stable_name_of_a_port_named_by_its_order(url: str, warned: bool, tmp_path: Path) -> None:
    r = runner.invoke(app, ["where", "-d", url, "--db", str(tmp_path / "s.db"), "--offline"])
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    assert ("named by the order the USB adapters were found" in text) is warned, text
    assert ("/dev/serial/by-id/" in text) is (warned or "by-id" in url)


def test_a_bluesky_move_on_another_controller_sends_nothing(RE: object) -> None:
    """The axis opens its controller once and moves it through `drive`: checked there too (bluesky/axis.py)."""
    pytest.importorskip("ophyd_async")
    import bluesky.plan_stubs as bps
    from bluesky.utils import FailedStatus
    from ophyd_async.core import init_devices

    from stickslip.bluesky import MoveError, StickSlipAxis

    cal = _sim_cal()
    with Store.open() as store:  # $STICKSLIP_DB (conftest): the axis's database
        move(store, MoveRequest("sim://", 3, by=1e-4, trust_calibration=True), cal)  # type: ignore[arg-type]
    other = SimulatedMM3A(seed=5)  # its info says sim://: another controller at the URL the positions are kept for
    with init_devices():
        axis = StickSlipAxis(other, 3, cal, name="q3")  # type: ignore[arg-type]
    with pytest.raises(FailedStatus) as e:
        RE(bps.mv(axis, 2e-3))  # type: ignore[operator]
    assert isinstance(e.value.__cause__, MoveError)
    assert "simulator seed 5, where the positions were kept for simulator seed 0" in str(e.value.__cause__)
    assert other.steps_simulated == 0
    with Store.open() as store:
        assert set(load_state(store, "sim://").why.values()) == {SWAPPED}


def test_an_arm_sharing_its_controller_is_told_to_re_reference_with_its_rig(tmp_path: Path) -> None:
    """A rig's arm on a shared controller keeps its positions (and its identity) under ``KEY#arm=NAME``: the advice
    names the arm, not ``-d URL`` (which would re-reference the controller's own key, not the arm's)."""
    from stickslip.devices.identity import check_controller
    from stickslip.devices.positions import JsonStateFile, save_state

    store = JsonStateFile(tmp_path / "state.json")
    state = load_state(store, "sim://#arm=probe")
    state.set_position(3, 2e-3)
    save_state(store, state)
    check_controller(store, "sim://", SimulatedMM3A(seed=0), [state])  # first opening: kept, nothing said
    assert kept_identity(store, "sim://#arm=probe") == "simulator seed 0" and kept_identity(store, "sim://") is None
    with pytest.raises(ControllerChanged, match=r"`stickslip where --rig RIG --arm probe --set J=min`"):
        check_controller(store, "sim://", SimulatedMM3A(seed=2), [state])
    assert load_state(store, "sim://#arm=probe").uncertain[3] == (0.0, kin.JOINTS[3].upper)


def _telling(identity: str) -> type[SimulatedMM3A]:
    """A simulator that tells ``identity`` (a third-party backend's text: anything a controller answers)."""
    from stickslip.devices.base import DeviceInfo

    class Telling(SimulatedMM3A):
        @property
        def info(self) -> DeviceInfo:
            base = super().info
            return DeviceInfo(base.url, "telling", base.joints, base.extra, identity)

    return Telling


@pytest.mark.parametrize("identity", [
    "FTDI token=A50285BI",  # a word the store's redaction takes for a secret: kept as 'token=***'
    "usb:0403:6001@bus1",  # user:password@ to the redaction
    "serial\x00A\nB\ud800",  # a NUL (PostgreSQL's jsonb refuses it), a line break, a lone surrogate (not printable)
    "S" * 10_000,
], ids=["token", "at", "control", "10kB"])
def test_an_identity_of_any_text_is_the_same_controller_at_the_next_opening(identity: str, tmp_path: Path) -> None:
    # the store redacts every text it keeps: an identity compared with what was kept of it differed at every
    # opening, so the same controller was refused as another one, every joint made uncertain, for ever
    cal = _sim_cal()
    opener = _telling(identity)
    with Store.open(tmp_path / "s.db") as store:
        req = MoveRequest("sim://", 3, by=1e-4, trust_calibration=True)
        for _ in range(2):
            r = move(store, req, cal, opener=lambda _url: opener(seed=0))  # type: ignore[arg-type]
            assert r.outcome.error is None and r.outcome.sent > 0
        assert load_state(store, "sim://").uncertain == {}
        kept = kept_identity(store, "sim://")
        assert kept is not None and kept.isprintable() and len(kept) <= 120
        other = _telling(identity[:-1] + "Z")
        with pytest.raises(ControllerChanged) as e:
            move(store, req, cal, opener=lambda _url: other(seed=0))  # type: ignore[arg-type]
        line = str(e.value)
        assert line.isprintable() and len(line) < 700 and "A50285BI" not in line, line


@pytest.mark.parametrize("row", ["not json{", '"simulator seed 0"', "[1, 2]", '{"identity": 7}'],
                         ids=["not-json", "a-string", "a-list", "a-number"])
def test_a_controller_row_that_cannot_be_read_is_kept_again_not_refused_for_ever(row: str, tmp_path: Path) -> None:
    # a row that is not JSON (a hand edit, a bad sector) refused every move of the controller with the store's error,
    # and nothing (a re-reference, where --set) wrote it again: blocked until it was deleted by hand. It is read as
    # a row of another type is, as nothing kept: the identity kept again at this opening
    import sqlite3

    cal = _sim_cal()
    req = MoveRequest("sim://", 3, by=1e-4, trust_calibration=True)
    with Store.open(tmp_path / "s.db") as store:
        move(store, req, cal)  # type: ignore[arg-type]
    with sqlite3.connect(tmp_path / "s.db") as con:
        assert con.execute("UPDATE device_state SET value = ? WHERE key = ?", (row, IDENTITY_KEY)).rowcount == 1
    with Store.open(tmp_path / "s.db") as store:
        r = move(store, req, cal)  # type: ignore[arg-type]
        assert r.outcome.error is None and r.outcome.sent > 0
        assert kept_identity(store, "sim://") == "simulator seed 0"
        assert load_state(store, "sim://").uncertain == {}
