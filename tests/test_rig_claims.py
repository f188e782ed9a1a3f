"""The Bluesky axes and the closed loop's legs claim their range, as ``move`` does (claim57).

rig48 made ``move`` and ``reach`` journal their whole planned range before they read the other
arms again ("mark, then check"); a Bluesky axis (``guard=``) and a closed-loop leg checked against
the other arms as they were kept when their guard was built, with no claim. The layout is
test_rig_race's: the probe (mount -30 mm) and the other arm (+30 mm, turned 180°) each moving joint
3 by +9 mm bring both tips to (0, 0, 0). Collision is judged by the independent geometry of
``rig_geometry`` (``test_rig_race.apart``), not by the envelope under test.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")

from server_support import RIG, true_calibration  # noqa: E402

from stickslip import kinematics as kin  # noqa: E402
from stickslip.bluesky import MoveError, StickSlipAxis, StickSlipManipulator  # noqa: E402
from stickslip.devices.base import open_device  # noqa: E402
from stickslip.devices.positions import load_state, save_state  # noqa: E402
from stickslip.procedures.arms import guard_for  # noqa: E402
from stickslip.procedures.closed_loop import CameraLoop, move_seen  # noqa: E402
from stickslip.procedures.move import MoveRefused, MoveRequest  # noqa: E402
from stickslip.rig import Rig, load_rig  # noqa: E402
from stickslip.storage import Store  # noqa: E402
from stickslip.vision.camera import open_camera  # noqa: E402
from test_rig_race import URLS, apart, arm_move  # noqa: E402


@pytest.fixture()
def rig(tmp_path: Path) -> Rig:
    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    return load_rig(path)


class _Opened:
    """A store for ``with``, that runs ``then()`` once, before the first write of ``key`` (the link's stores)."""

    def __init__(self, inner: Store, key: str, then: Callable[[], None], done: list[bool]):
        self.inner, self.key, self.then, self.done = inner, key, then, done

    def __enter__(self) -> _Opened:
        return self

    def __exit__(self, *exc: object) -> None:
        self.inner.close()

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        if device == self.key and not self.done:
            self.done.append(True)
            self.then()
        self.inner.set_state(device, key, value_json)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def interleave(link: Any, db: Path, key: str, then: Callable[[], None]) -> None:
    """Every store ``link`` opens runs ``then()`` before the first write of ``key`` (once in all)."""
    done: list[bool] = []
    link.store = lambda: _Opened(Store.open(db), key, then, done)


def other_axis(store: Store, rig: Rig, db: Path) -> StickSlipAxis:
    """Joint 3 of arm 'other' as a Bluesky axis, with the rig's guard (docs/bluesky.md)."""
    return StickSlipAxis(URLS["other"], 3, true_calibration(URLS["other"]), name="q3", db=db,
                         guard=guard_for(store, rig, "other"))


async def _set(axis: Any, target: float) -> None:
    await axis.connect()
    await axis.set(target)


def kept(store: Store, rig: Rig, arm: str) -> Any:
    return load_state(store, rig.state_key(arm), rig.arm(arm).joint_specs())


def test_a_bluesky_axis_checks_the_other_arms_as_kept_when_it_moves(rig: Rig, tmp_path: Path) -> None:
    # its guard was built with the manipulator; the probe moved 9 mm after that: before claim57 the axis checked
    # against the probe where it was when the guard was built, and moved into it (both tips at (0, 0, 0))
    db = tmp_path / "rig.db"
    store = Store.open(db)
    axis = other_axis(store, rig, db)
    assert arm_move(store, rig, "probe").outcome.error is None
    with pytest.raises(MoveError, match="arm 'other': .*arm probe"):
        asyncio.run(_set(axis, 9e-3))
    assert kept(store, rig, "other").positions[3] == 0.0 and not kept(store, rig, "other").claim
    assert apart(store, rig) > 1e-3


def test_a_move_started_between_a_bluesky_axiss_read_and_its_first_write_is_seen(rig: Rig, tmp_path: Path) -> None:
    # the probe's whole move runs after the axis has read the rig, before its first write of its own state: before
    # claim57 the axis had checked against the probe at rest and journalled its first burst after; both moved
    db = tmp_path / "rig.db"
    store = Store.open(db)
    axis = other_axis(store, rig, db)
    probe: list[Any] = []
    interleave(axis.link, db, rig.state_key("other"), lambda: probe.append(arm_move(Store.open(db), rig, "probe")))
    with pytest.raises(MoveError, match="arm 'other': .*arm probe"):
        asyncio.run(_set(axis, 9e-3))
    assert probe and probe[0].outcome.error is None and probe[0].outcome.sent > 0  # the probe moved
    other = kept(store, rig, "other")
    assert other.positions[3] == 0.0 and not other.claim and not other.uncertain
    assert apart(store, rig) > 1e-3


def test_a_move_started_during_a_bluesky_move_sees_its_claim(rig: Rig, tmp_path: Path) -> None:
    # the probe's move starts at the axis's first write: it now sees the axis's claim and is refused; the axis moves
    db = tmp_path / "rig.db"
    store = Store.open(db)
    axis = other_axis(store, rig, db)
    refused: list[str] = []

    def probe_move() -> None:
        try:
            arm_move(Store.open(db), rig, "probe")
        except MoveRefused as e:
            refused.append(str(e))

    seen: list[Any] = []

    class Watch(_Opened):  # the probe's move at the axis's first write, once that write is made
        def set_state(self, device: str, key: str, value_json: Any) -> None:
            self.inner.set_state(device, key, value_json)
            if device == rig.state_key("other") and key == "positions":  # not the controller's identity
                seen.append(dict(self.inner.get_state(device, key)))
                if len(seen) == 1:
                    probe_move()

    axis.link.store = lambda: Watch(Store.open(db), "", lambda: None, [True])  # type: ignore[method-assign]
    asyncio.run(_set(axis, 9e-3))
    assert len(refused) == 1 and "arm 'probe': arm 'other' may be anywhere along a move" in refused[0], refused
    assert seen[0].get("claim", {}).get("3") == pytest.approx([0.0, 9e-3])  # the first write is the claim
    assert all(s.get("claim") for s in seen[1:-1]) and "claim" not in seen[-1]  # kept over every burst, then gone
    assert kept(store, rig, "probe").positions[3] == 0.0 and kept(store, rig, "other").positions[3] > 8e-3
    assert apart(store, rig) > 1e-3


def test_a_bluesky_tip_move_claims_its_range(rig: Rig, tmp_path: Path) -> None:
    # the tip's straight move (tip.x) is checked and claimed as `reach --rig` is: the probe's move, run between the
    # tip's read and its first write, is seen (before claim57 both moved)
    db = tmp_path / "rig.db"
    store = Store.open(db)
    arm = StickSlipManipulator(URLS["other"], true_calibration(URLS["other"]), name="other", db=db,
                               guard=guard_for(store, rig, "other"))
    probe: list[Any] = []
    interleave(arm.link, db, rig.state_key("other"), lambda: probe.append(arm_move(Store.open(db), rig, "probe")))
    q = kept(store, rig, "other").positions
    x0 = float(kin.tip((q[1], q[2], q[3]))[0])  # its tip, base frame: straight out along x
    with pytest.raises(MoveError, match="arm 'other': .*arm probe"):
        asyncio.run(_set(arm.tip.x, x0 + 9e-3))  # joint 3 by +9 mm, as the probe's: the tips meet
    assert probe and probe[0].outcome.sent > 0
    other = kept(store, rig, "other")
    assert other.positions[3] == 0.0 and not other.claim and not other.uncertain
    assert apart(store, rig) > 1e-3


# ---------------------------------------------------------------- the closed loop's legs


def placed(store: Store, rig: Rig, probe: float, other: float) -> None:
    """Both arms' joint 3 set (referenced) at ``probe`` and ``other`` (m): their tips 18 mm - probe - other apart."""
    for arm, q in (("probe", probe), ("other", other)):
        s = kept(store, rig, arm)
        s.set_position(3, q, "set")
        save_state(store, s)


def probe_loop(store: Any, rig: Rig, by: float, opener: Any = None) -> Any:
    """The probe's joint 3 moved by ``by`` (m) with the camera (``move --rig --camera``), 1 µm pixels, 16 px legs."""
    url = "simcam://?pixel=1um&size=512x128&centre=tip"
    dev = open_device(URLS["probe"])
    dev.set_pose(*kept(store, rig, "probe").pose)
    cam = open_camera(url, dev)
    (x, y), _ = cam.true_tip()
    cam.close()
    request = MoveRequest(URLS["probe"], 3, by=by, burst=500, guard=guard_for(store, rig, "probe"),
                          joints=rig.arm("probe").joint_specs(), state_key=rig.state_key("probe"))
    return move_seen(store, request, true_calibration(URLS["probe"]), CameraLoop(url, tip=(float(x), float(y))),
                     opener=opener)


class AtFirstLook:
    """A store that runs ``then()`` once, after the probe's first save of a position the camera has seen."""

    def __init__(self, inner: Store, key: str, then: Callable[[], None]):
        self.inner, self.key, self.then, self.done = inner, key, then, False

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        self.inner.set_state(device, key, value_json)
        if device == self.key and not self.done and "seen" in str(value_json.get("sources")):
            self.done = True
            self.then()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def test_a_move_started_between_two_legs_of_the_closed_loop_sees_its_claim(rig: Rig, tmp_path: Path) -> None:
    # tips 1.35 mm apart; the probe's loop goes 200 µm towards the other arm (1.15 mm left, clear). After its first
    # leg and look the other arm's move of 200 µm starts: before claim57 it saw the probe at rest 1.33 mm away and
    # moved, and the loop's next legs (checked against the other arm as kept when the loop began) took the probe
    # on: 0.95 mm apart at the end, inside the 1 mm kept. Now the loop's claim (8 to 8.2 mm) refuses that move.
    store = Store.open(tmp_path / "rig.db")
    placed(store, rig, 8e-3, 8.65e-3)
    other: list[Any] = []

    def other_move() -> None:
        try:
            other.append(arm_move(store, rig, "other", by=200e-6))
        except MoveRefused as e:
            other.append(str(e))

    r = probe_loop(AtFirstLook(store, rig.state_key("probe"), other_move), rig, 200e-6)
    assert r.reached and len(r.looks) > 2
    assert len(other) == 1 and isinstance(other[0], str), other
    assert "arm 'other': arm 'probe' may be anywhere along a move (a move of it claims its joint 3 between 8000 µm " \
           "and 8200 µm until it ends)" in other[0]
    assert kept(store, rig, "other").positions[3] == 8.65e-3 and not kept(store, rig, "probe").claim
    assert apart(store, rig) > 1e-3


def test_each_leg_reads_the_other_arms_again(rig: Rig, tmp_path: Path) -> None:
    # the other arm moved without a claim (a jog claims none; a process of an older release) after the loop began:
    # before claim57 each leg was checked against the other arm as kept when the loop began and the probe went on
    # to 0.95 mm of it; now the next leg is refused, naming it, and the claim is taken back
    store = Store.open(tmp_path / "rig.db")
    placed(store, rig, 8e-3, 8.65e-3)

    def jogged() -> None:
        s = kept(store, rig, "other")
        s.set_position(3, 8.85e-3, "dead-reckoned")
        save_state(store, s)

    r = probe_loop(AtFirstLook(store, rig.state_key("probe"), jogged), rig, 200e-6)
    assert not r.reached and r.reason is not None
    assert r.reason.startswith("the next leg was refused by the rig's envelope: ") and "arm other" in r.reason
    probe = kept(store, rig, "probe")
    assert not probe.claim and not probe.uncertain and 8e-3 < probe.positions[3] < 8.2e-3
    assert apart(store, rig) > 1e-3


def test_ctrl_c_in_the_closed_loop_takes_its_claim_back(rig: Rig, tmp_path: Path) -> None:
    from stickslip.procedures.move import Interrupted

    store = Store.open(tmp_path / "rig.db")
    placed(store, rig, 8e-3, 8.65e-3)
    steps: list[int] = []

    class CtrlCOnThirdLeg:
        def __init__(self, url: str) -> None:
            self.dev = open_device(url)

        def step(self, joint: int, n: int) -> None:
            steps.append(n)
            if len(steps) == 3:
                raise KeyboardInterrupt
            self.dev.step(joint, n)

        def __getattr__(self, name: str) -> Any:
            return getattr(self.dev, name)

    with pytest.raises(Interrupted) as e:
        probe_loop(store, rig, 200e-6, opener=CtrlCOnThirdLeg)
    assert e.value.state is not None and not e.value.state.claim  # what it says is kept: no claim
    probe = kept(store, rig, "probe")
    assert not probe.claim and 3 in probe.uncertain  # the interrupted leg: uncertain over it, as before


def test_a_leg_beyond_the_claim_widens_it_before_the_others_are_read() -> None:
    # a correction may go past the planned end: its range is claimed (written) before the other arms are read again
    from stickslip.procedures.move import claim_and_check
    from stickslip.rig.guard import Guard
    from stickslip.rig.model import Rig as RigModel
    from test_envelope import mm3a

    stored: list[dict[int, tuple[float, float]]] = []

    class Kept:
        def __init__(self) -> None:
            self.raw: Any = None

        def get_state(self, device: str, key: str) -> Any:
            return self.raw

        def set_state(self, device: str, key: str, value_json: Any) -> None:
            self.raw = value_json

    store = Kept()
    rig1 = RigModel("r", "r", (mm3a(),), ())
    state = load_state(store, "sim://")
    state.claim[3] = (0.0, 2e-3)
    save_state(store, state)

    def read_again() -> Guard:
        stored.append(load_state(store, "sim://").claim)
        return Guard(rig1, "a")

    guard = Guard(rig1, "a", fresh=read_again)
    claim_and_check(store, state, guard, [[0.0, -1.5, 1.9e-3], [0.0, -1.5, 2.1e-3]], widen=True)
    assert stored == [{3: (0.0, 2.1e-3)}] and state.claim == {3: (0.0, 2.1e-3)}
    claim_and_check(store, state, guard, [[0.0, -1.5, 2.1e-3], [0.0, -1.5, 2.05e-3]], widen=True)
    assert stored[-1] == {3: (0.0, 2.1e-3)} and len(stored) == 2  # within the claim: read again, nothing written


# ---------------------------------------------------------------- the rig's STOP


class PressesAtSecondBurst:
    """arm 'other''s simulator; the rig's STOP is pressed for arm 'probe' (its page) once its second burst is made."""

    def __init__(self, db: Path, rig: Rig) -> None:
        self.dev, self.db, self.rig, self.bursts = open_device(URLS["other"]), db, rig, []

    def step(self, joint: int, n: int) -> None:
        from stickslip.procedures import rigstop

        self.dev.step(joint, n)
        self.bursts.append(n)
        if len(self.bursts) == 2:
            with Store.open(self.db) as store:  # (the move's worker thread: a store of its own)
                rigstop.press(store, self.rig, "probe")

    def __getattr__(self, name: str) -> Any:
        return getattr(self.dev, name)


@pytest.mark.parametrize("axis", ["joint", "tip"])
def test_a_bluesky_move_ends_at_the_rigs_stop_with_its_position_exact(rig: Rig, tmp_path: Path, axis: str) -> None:
    # before claim57 a Bluesky axis did not read the rig's STOP: the move ran to its end (9 mm, 45 bursts)
    from stickslip.procedures import rigstop

    db = tmp_path / "rig.db"
    store = Store.open(db)
    rigstop.press(store, rig, "probe")  # pressed before the move began: does not stop it
    dev = PressesAtSecondBurst(db, rig)
    arm = StickSlipManipulator(dev, true_calibration(URLS["other"]), name="other", db=db, burst=200,
                               guard=guard_for(store, rig, "other"))
    q = kept(store, rig, "other").positions
    moving = arm.q3 if axis == "joint" else arm.tip.x
    target = 6e-3 if axis == "joint" else float(kin.tip((q[1], q[2], q[3]))[0]) + 6e-3
    with pytest.raises(MoveError) as e:
        asyncio.run(_set(moving, target))
    line = str(e.value)
    assert "stopped by the rig's STOP (pressed for arm 'probe'" in line and "\n" not in line, line
    assert "uncertain" not in line, line
    assert len(dev.bursts) == 2  # no further burst
    other = kept(store, rig, "other")
    assert not other.uncertain and not other.claim
    assert other.positions[3] == pytest.approx(dev.dev.position(3), abs=2e-6)  # exact: where the arm is
    assert 0.0 < other.positions[3] < 6e-3


def test_the_closed_loop_ends_at_the_rigs_stop_with_its_position_exact(rig: Rig, tmp_path: Path) -> None:
    # `move --rig --camera` opens its controller through rigstop.stoppable (the CLI): a press for another arm during
    # the loop ends it before its next burst, exact, its claim taken back
    from stickslip.procedures import rigstop
    from stickslip.procedures.arms import opener_for

    store = Store.open(tmp_path / "rig.db")
    placed(store, rig, 8e-3, 6e-3)
    bursts: list[int] = []

    class PressesAtThirdLeg:
        def __init__(self, url: str) -> None:
            self.dev = open_device(url)

        def step(self, joint: int, n: int) -> None:
            self.dev.step(joint, n)
            bursts.append(n)
            if len(bursts) == 2:
                rigstop.press(store, rig, "other")

        def __getattr__(self, name: str) -> Any:
            return getattr(self.dev, name)

    opener = rigstop.stoppable(opener_for(rig, "probe", PressesAtThirdLeg), store, rig, "probe")
    r = probe_loop(store, rig, 200e-6, opener=opener)
    assert not r.reached and r.reason is not None and len(bursts) == 2
    assert r.reason.startswith("stopped by the rig's STOP (pressed for arm 'other'"), r.reason
    assert r.reason.endswith("no further burst sent"), r.reason  # was: '... (a limit: the device stopped the move)'
    probe = kept(store, rig, "probe")
    assert not probe.uncertain and not probe.claim
    assert r.sim_true is not None and probe.positions[3] == pytest.approx(r.sim_true[2], abs=1e-6)


def test_a_bluesky_axis_with_the_camera_ends_at_the_rigs_stop(rig: Rig, tmp_path: Path) -> None:
    # the closed loop through a Bluesky axis (camera=) reads the rig's STOP too, and claims its legs
    db = tmp_path / "rig.db"
    store = Store.open(db)
    placed(store, rig, 0.0, 8e-3)
    dev = PressesAtSecondBurst(db, rig)
    dev.dev.set_pose(*kept(store, rig, "other").pose)
    url = "simcam://?pixel=1um&size=512x128&centre=tip"
    cam = open_camera(url, dev.dev)
    (x, y), _ = cam.true_tip()
    cam.close()
    axis = StickSlipAxis(dev, 3, true_calibration(URLS["other"]), name="q3", db=db, burst=200,
                         camera=CameraLoop(url, tip=(float(x), float(y))), guard=guard_for(store, rig, "other"))
    with pytest.raises(MoveError) as e:
        asyncio.run(_set(axis, 8.2e-3))
    assert "the closed loop stopped: stopped by the rig's STOP (pressed for arm 'probe'" in str(e.value), str(e.value)
    assert len(dev.bursts) == 2
    other = kept(store, rig, "other")
    assert not other.uncertain and not other.claim
    assert other.positions[3] == pytest.approx(dev.dev.position(3), abs=1e-6)


def test_a_bluesky_axis_on_another_device_than_its_arms_is_refused(rig: Rig, tmp_path: Path) -> None:
    # arm 'other''s guard given to an axis on the probe's controller: its claim would be kept under sim://, where
    # the other arms read the probe, not arm 'other'; before claim57 it moved (checked as arm 'other' at rest)
    db = tmp_path / "rig.db"
    store = Store.open(db)
    axis = StickSlipAxis(URLS["probe"], 3, true_calibration(URLS["probe"]), name="q3", db=db,
                         guard=guard_for(store, rig, "other"))
    with pytest.raises(MoveError, match="arm 'other' of the rig is kept under 'sim://\\?seed=2', and this axis's "
                                        "device under 'sim://'"):
        asyncio.run(_set(axis, 1e-3))
    assert kept(store, rig, "probe").positions[3] == 0.0 and not kept(store, rig, "probe").claim


def test_a_bluesky_stop_takes_the_claim_back_and_a_killed_ones_says_so(rig: Rig, tmp_path: Path) -> None:
    # stop() at the second burst: the claim (held over the bursts) is gone after, the position exact. A session
    # killed there (its kept state put back as it was then) leaves the claim, and the other arms say so as for a
    # move's, until the arm is re-referenced
    from stickslip.procedures.move import where_line

    db = tmp_path / "rig.db"
    store = Store.open(db)
    held: list[Any] = []
    key = rig.state_key("other")

    class StopsAtSecondBurst(PressesAtSecondBurst):
        def step(self, joint: int, n: int) -> None:
            self.dev.step(joint, n)
            self.bursts.append(n)
            if len(self.bursts) == 2:
                with Store.open(self.db) as s:
                    held.append(s.get_state(key, "positions"))
                axis._stop_event.set()  # what stop() does first: no further burst

    dev = StopsAtSecondBurst(db, rig)
    axis = StickSlipAxis(dev, 3, true_calibration(URLS["other"]), name="q3", db=db, burst=200,
                         guard=guard_for(store, rig, "other"))
    with pytest.raises(RuntimeError, match="was stopped after 400 of"):
        asyncio.run(_set(axis, 9e-3))
    assert held and held[0]["claim"] == {"3": [0.0, pytest.approx(9e-3)]}  # claimed while it moved
    other = kept(store, rig, "other")
    assert not other.claim and not other.uncertain
    assert other.positions[3] == pytest.approx(dev.dev.position(3), abs=2e-6)
    store.set_state(key, "positions", held[0])  # killed at the second burst: its claim left behind
    assert "claimed by a move: joint 3 0 µm to 9000 µm" in where_line(kept(store, rig, "other"))
    with pytest.raises(MoveRefused, match="a move of it claims its joint 3 between 0 µm and 9000 µm until it ends"):
        arm_move(store, rig, "probe")
    s = kept(store, rig, "other")
    s.set_position(3, s.positions[3], "set")  # re-referenced
    save_state(store, s)
    assert not kept(store, rig, "other").claim


# ---------------------------------------------------------------- the jog


@pytest.mark.parametrize("single_step", [False, True])
def test_a_jogs_single_steps_are_checked_against_the_rig_as_its_ticks_are(single_step: bool) -> None:
    # single-step mode (a press moves the tip by the preset distance, sent as a straight move's segments): before
    # claim57 its segments were sent without a look at the rig's envelope, 91 steps here where every path is
    # refused (another arm claimed with no box); a held key's ticks were stopped, and are
    import math

    from stickslip.procedures.jog import JogController
    from stickslip.rig.guard import Guard
    from stickslip.rig.model import Rig as RigModel
    from test_envelope import mm3a
    from test_reach import CAL

    rig1 = RigModel("r", "r", (mm3a(),), ())
    refused = Guard(rig1, "a", unknown={"b": "a move of it claims its joint 3 between 0 µm and 9000 µm"})
    c = JogController(CAL, [0.0, -math.pi / 2, 0.002], speed_index=6, hold=0.0, guard=refused,
                      single_step=single_step)
    c.press("a", 0.0)
    sent = 0
    for k in range(40):
        steps = c.tick(0.05 * k, 0.05)
        sent += sum(abs(n) for n in steps)
        for j, n in enumerate(steps, start=1):
            c.sent_steps(j, n)
    assert sent == 0 and c.message == "stopped at the rig's envelope (arm b): move another way"
    c = JogController(CAL, [0.0, -math.pi / 2, 0.002], speed_index=6, hold=0.0, guard=Guard(rig1, "a"),
                      single_step=single_step)
    c.press("a", 0.0)
    assert sum(abs(n) for k in range(40) for n in c.tick(0.05 * k, 0.05)) > 0  # a clear rig: it moves


def test_a_jogs_tick_claims_its_range_before_it_reads_the_other_arms(rig: Rig, tmp_path: Path) -> None:
    # each tick read the other arms, then journalled its burst: a move of another arm started in between saw the
    # jog's arm at rest where it was a tick before (before claim57, nothing of the jog at the first tick's journal).
    # Now the tick's range is written first, so that move is kept from it; taken back once the jog stands still
    from stickslip.procedures.arms import opener_for
    from stickslip.procedures.jog import JogRequest, jog

    store = Store.open(tmp_path / "rig.db")
    key = rig.state_key("probe")
    seen: list[dict[str, str]] = []
    claims: list[Any] = []

    class Journal:  # at the jog's burst journals (a joint in flight): what another arm's move reads of the probe
        def set_state(self, device: str, k: str, value_json: Any) -> None:
            if device == key and value_json.get("uncertain") and len(seen) < 3:
                seen.append(dict(guard_for(store, rig, "other").unknown))
            store.set_state(device, k, value_json)
            if device == key:
                claims.append(value_json.get("claim"))

        def __getattr__(self, name: str) -> Any:
            return getattr(store, name)

    class Keys:
        ticks = [["d"]] + [[]] * 5 + [["space"]] + [[]] * 3 + [["q"]]

        def read(self, timeout: float) -> list[str]:
            return self.ticks.pop(0) if self.ticks else ["q"]

        def close(self) -> None:
            pass

    clock = iter(0.05 * k for k in range(1000))
    request = JogRequest(URLS["probe"], speed=6, hold=0.0, guard=guard_for(store, rig, "probe"),
                         joints=rig.arm("probe").joint_specs(), state_key=key)
    r = jog(Journal(), request, true_calibration(URLS["probe"]), keys=Keys, show=lambda s: None,
            clock=lambda: next(clock), opener=opener_for(rig, "probe"))
    assert r.error is None and kept(store, rig, "probe").positions[3] > 0.0  # it moved
    assert len(seen) == 3 and all("a move of it claims its joint" in u.get("probe", "") for u in seen), seen
    assert claims[-1] is None and not kept(store, rig, "probe").claim  # taken back
    held = [c for c in claims if c]
    assert held and all(set(c) <= {"1", "2", "3"} for c in held)
    assert max(hi - lo for c in held for lo, hi in c.values()) < 20e-6  # a tick's range (100 µm/s, 0.1 s at most)


def test_a_bluesky_camera_axis_on_another_device_than_its_arms_is_refused(rig: Rig, tmp_path: Path) -> None:
    # the same mismatch through the closed loop (camera=): its legs claimed under sim://, where the other arms read
    # the probe, and it was checked as arm 'other' at rest; the joint move refused it (hold_claim), this one moved
    db = tmp_path / "rig.db"
    store = Store.open(db)
    dev = open_device(URLS["probe"])
    url = "simcam://?pixel=1um&size=512x128&centre=tip"
    cam = open_camera(url, dev)
    (x, y), _ = cam.true_tip()
    cam.close()
    axis = StickSlipAxis(dev, 3, true_calibration(URLS["probe"]), name="q3", db=db, burst=200,
                         camera=CameraLoop(url, tip=(float(x), float(y))), guard=guard_for(store, rig, "other"))
    with pytest.raises(MoveError, match="arm 'other' of the rig is kept under 'sim://\\?seed=2', and this axis's "
                                        "device under 'sim://'"):
        asyncio.run(_set(axis, 2e-4))
    assert dev.steps_simulated == 0  # type: ignore[attr-defined]
    assert kept(store, rig, "probe").positions[3] == 0.0 and not kept(store, rig, "probe").claim
