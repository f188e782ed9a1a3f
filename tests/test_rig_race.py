"""Two arms of one rig moved at once: "mark, then check" (rig48).

audit46 measured 12 of 12 simultaneous pairs of moves both accepted: each move read the other
arms, then journalled its own first burst. Here the two moves' steps are interleaved by hand (a
store that runs the other arm's move at the moment the first one writes its own state for the
first time) and then raced in threads. The paths collide: the probe (mount -30 mm) and the other
arm (+30 mm, turned 180°) each moving joint 3 by +9 mm bring both tips to (0, 0, 0). Collision is
judged by the independent geometry of ``rig_geometry`` (points along the links), not by the
envelope under test.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rig_geometry import links, point_segment
from server_support import RIG, true_calibration

from stickslip.devices.positions import load_state
from stickslip.procedures.arms import guard_for, opener_for
from stickslip.procedures.move import MoveRefused, MoveRequest, MoveResult, move
from stickslip.rig import Rig, load_rig
from stickslip.storage import Store

URLS = {"probe": "sim://", "other": "sim://?seed=2"}


@pytest.fixture()
def rig(tmp_path: Path) -> Rig:
    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    return load_rig(path)


def arm_move(store: Any, rig: Rig, arm: str, by: float = 9e-3) -> MoveResult:
    """``arm``'s joint 3 by ``by`` (m), as ``stickslip move --rig`` drives it (its guard read when it is called)."""
    a = rig.arm(arm)
    request = MoveRequest(URLS[arm], 3, by=by, burst=500, guard=guard_for(store, rig, arm), joints=a.joint_specs(),
                          state_key=rig.state_key(arm))
    return move(store, request, true_calibration(URLS[arm]), opener=opener_for(rig, arm))


def apart(store: Any, rig: Rig) -> float:
    """The two arms' least distance as kept now (links sampled, rig frame), m."""
    segs = {}
    for name in URLS:
        s = load_state(store, rig.state_key(name), rig.arm(name).joint_specs())
        segs[name] = links(rig.arm(name), np.asarray([s.positions[j] for j in (1, 2, 3)]))
    u = np.linspace(0.0, 1.0, 200)[:, None]
    pts = np.vstack([a + u * (b - a) for a, b in segs["probe"]])
    return float(min(np.min(point_segment(pts, a, b)) for a, b in segs["other"]))


class Interleaved:
    """A store that runs ``then()`` once, at the first write of ``key`` (before or after it is written)."""

    def __init__(self, inner: Store, key: str, then: Callable[[], None], after: bool = False):
        self.inner, self.key, self.then, self.after, self.done = inner, key, then, after, False

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        first = device == self.key and not self.done
        self.done = self.done or first
        if first and not self.after:
            self.then()
        self.inner.set_state(device, key, value_json)
        if first and self.after:
            self.then()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def test_the_other_arm_moving_between_read_and_mark_is_seen(rig: Rig, tmp_path: Path) -> None:
    # the other arm's whole move runs after the probe has read the rig but before its first write: before
    # rig48 the probe checked against the other arm's old pose, and both moved (tips 0.28 µm apart)
    store = Store.open(tmp_path / "rig.db")
    other: list[MoveResult] = []
    wrapped = Interleaved(store, rig.state_key("probe"), lambda: other.append(arm_move(store, rig, "other")))
    with pytest.raises(MoveRefused) as e:
        arm_move(wrapped, rig, "probe")
    assert other and other[0].outcome.error is None and other[0].outcome.sent > 0  # the other arm moved
    line = str(e.value)
    assert "\n" not in line and "arm 'probe'" in line and "arm other" in line, line
    kept = load_state(store, rig.state_key("probe"), rig.arm("probe").joint_specs())
    assert kept.positions[3] == 0.0 and not kept.uncertain and not kept.claim  # not moved, no claim left
    assert apart(store, rig) > 1e-3  # the arms are the rig's arm_distance (1 mm) apart or more


def test_the_other_arm_starting_after_the_mark_is_refused(rig: Rig, tmp_path: Path) -> None:
    # the other arm starts right after the probe's claim is written: it sees the claim, is refused, the probe moves
    store = Store.open(tmp_path / "rig.db")
    refused: list[str] = []

    def other_move() -> None:
        try:
            arm_move(store, rig, "other")
        except MoveRefused as e:
            refused.append(str(e))

    wrapped = Interleaved(store, rig.state_key("probe"), other_move, after=True)
    r = arm_move(wrapped, rig, "probe")
    assert r.outcome.error is None and r.outcome.sent > 0
    assert len(refused) == 1, refused
    assert "arm 'other': arm 'probe'" in refused[0] and "a move of it claims its joint 3 between 0 µm and" in refused[0]
    assert "two moves started at once are both refused" in refused[0] and "\n" not in refused[0]
    for name in URLS:  # no claim left by either; the refused arm did not move
        kept = load_state(store, rig.state_key(name), rig.arm(name).joint_specs())
        assert not kept.claim and not kept.uncertain
    assert load_state(store, rig.state_key("other"), rig.arm("other").joint_specs()).positions[3] == 0.0
    assert apart(store, rig) > 1e-3


def test_a_claim_covers_the_gap_between_bursts(rig: Rig, tmp_path: Path) -> None:
    # between one burst's "done" and the next one's mark the arm looked still; the claim keeps it claimed
    store = Store.open(tmp_path / "rig.db")
    seen: list[dict[str, Any]] = []

    class Watch:
        def set_state(self, device: str, key: str, value_json: Any) -> None:
            store.set_state(device, key, value_json)
            if device == rig.state_key("probe") and key == "positions":  # not the controller's identity
                seen.append(dict(store.get_state(device, key)))

        def __getattr__(self, name: str) -> Any:
            return getattr(store, name)

    r = arm_move(Watch(), rig, "probe", by=2e-3)
    assert len(r.outcome.bursts) >= 3
    during = seen[1:-1]  # every save after the claim, before it is taken back
    assert len(during) >= 2 * len(r.outcome.bursts)
    assert all(s.get("claim", {}).get("3") == [0.0, 2e-3] for s in during), [s.get("claim") for s in seen]
    assert any(not s.get("uncertain") for s in during)  # a "done" save: not in flight, still claimed
    assert "claim" not in seen[-1] and not load_state(store, rig.state_key("probe")).claim


def test_a_re_reference_clears_a_claim_left_behind(rig: Rig, tmp_path: Path) -> None:
    from stickslip.devices.positions import save_state

    store = Store.open(tmp_path / "rig.db")
    key, specs = rig.state_key("other"), rig.arm("other").joint_specs()
    s = load_state(store, key, specs)
    s.claim_path([[0.0, -1.5, 0.0], [0.0, -1.5, 9e-3]])  # a process that ended without taking it back
    save_state(store, s)
    # rig52: the probe is kept from the claimed sweep (not refused outright), so the refused move is the one into
    # it (9 mm: both tips at (0, 0, 0)); a 1 mm move, 8 mm clear of the sweep, was refused here before rig52
    with pytest.raises(MoveRefused, match="a move of it claims its joint 3 between 0 µm and 9000 µm"):
        arm_move(store, rig, "probe", by=9e-3)
    s = load_state(store, key, specs)
    s.set_position(3, 0.0, "set")
    save_state(store, s)
    assert arm_move(store, rig, "probe", by=1e-3).outcome.error is None


def test_simultaneous_pairs_never_both_move_into_collision(rig: Rig, tmp_path: Path) -> None:
    # N pairs started together (a barrier) in threads, each thread its own connection: both refused is allowed,
    # both moved is not (the paths collide)
    counts = {"both moved": 0, "one moved": 0, "both refused": 0}
    for k in range(8):
        db = tmp_path / f"pair{k}.db"
        Store.open(db).close()
        go = threading.Barrier(2)
        moved: dict[str, bool] = {}

        def run(name: str, db: Path = db, go: threading.Barrier = go, moved: dict[str, bool] = moved) -> None:
            store = Store.open(db)
            try:
                go.wait(timeout=30)
                moved[name] = arm_move(store, rig, name).outcome.sent > 0
            except MoveRefused:
                moved[name] = False
            finally:
                store.close()

        threads = [threading.Thread(target=run, args=(name,)) for name in URLS]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
        assert set(moved) == set(URLS)
        n = sum(moved.values())
        counts[("both refused", "one moved", "both moved")[n]] += 1
        store = Store.open(db)
        try:
            assert apart(store, rig) > 1e-3 or n < 2
            for name in URLS:
                assert not load_state(store, rig.state_key(name), rig.arm(name).joint_specs()).claim
        finally:
            store.close()
    assert counts["both moved"] == 0, counts


def test_a_command_driving_an_arm_stops_at_the_rigs_stop(rig: Rig, tmp_path: Path) -> None:
    # `stickslip move --rig R --arm probe` opens its controller through rigstop.stoppable: the rig's STOP pressed
    # for another arm (its page) while the move runs ends it before its next burst, its position kept exact
    from stickslip.devices.base import open_device
    from stickslip.procedures import rigstop

    store = Store.open(tmp_path / "rig.db")
    rigstop.press(store, rig, "other")  # pressed before the move began: does not stop it
    sent: list[int] = []

    class PressesDuringSecondBurst:
        def __init__(self, url: str) -> None:
            self.dev = open_device(url)

        def step(self, joint: int, n: int) -> None:
            self.dev.step(joint, n)
            sent.append(n)
            if len(sent) == 1:
                rigstop.press(store, rig, "probe")  # its own arm's press: its process stopped itself already
            if len(sent) == 2:
                rigstop.press(store, rig, "other")

        def __getattr__(self, name: str) -> Any:
            return getattr(self.dev, name)

    a = rig.arm("probe")
    request = MoveRequest(URLS["probe"], 3, by=3e-3, burst=500, guard=guard_for(store, rig, "probe"),
                          joints=a.joint_specs(), state_key=rig.state_key("probe"))
    opener = rigstop.stoppable(opener_for(rig, "probe", PressesDuringSecondBurst), store, rig, "probe")
    r = move(store, request, true_calibration(URLS["probe"]), opener=opener)
    assert len(sent) == 2 and r.outcome.bursts == sent and abs(r.plan.steps) > 1000
    assert r.outcome.error is not None and "stopped by the rig's STOP (pressed for arm 'other'" in r.outcome.error
    kept = load_state(store, rig.state_key("probe"), a.joint_specs())
    assert not kept.uncertain and not kept.claim and kept.positions[3] == r.plan.position_after(sum(sent))
    assert rigstop.pressed(store, rig)["count"] == 3


@pytest.mark.parametrize("fault", ["ctrl-c", "device error"])
def test_an_interrupted_move_takes_its_claim_back_and_stays_uncertain(rig: Rig, tmp_path: Path, fault: str) -> None:
    # the claim is the move's, not the journal's: Ctrl-C or a device error mid-burst leaves the joint uncertain
    # over that burst (as before), and the claim gone, so the other arm is refused for the uncertainty alone
    from stickslip.devices.base import DeviceError, open_device
    from stickslip.procedures.move import Interrupted

    store = Store.open(tmp_path / "rig.db")

    class FailsSecondBurst:
        def __init__(self, url: str) -> None:
            self.dev, self.n = open_device(url), 0

        def step(self, joint: int, n: int) -> None:
            self.n += 1
            if self.n == 2:
                raise KeyboardInterrupt if fault == "ctrl-c" else DeviceError("link dropped")
            self.dev.step(joint, n)

        def __getattr__(self, name: str) -> Any:
            return getattr(self.dev, name)

    a = rig.arm("probe")
    request = MoveRequest(URLS["probe"], 3, by=3e-3, burst=500, guard=guard_for(store, rig, "probe"),
                          joints=a.joint_specs(), state_key=rig.state_key("probe"))
    if fault == "ctrl-c":
        with pytest.raises(Interrupted):
            move(store, request, true_calibration(URLS["probe"]), opener=opener_for(rig, "probe", FailsSecondBurst))
    else:
        r = move(store, request, true_calibration(URLS["probe"]), opener=opener_for(rig, "probe", FailsSecondBurst))
        assert r.outcome.error == "link dropped" and r.outcome.sent > 0
    kept = load_state(store, rig.state_key("probe"), a.joint_specs())
    assert not kept.claim and 3 in kept.uncertain
    lo, hi = kept.uncertain[3]
    assert 0.0 < lo < hi < 3e-3  # the second burst's range only, not the whole move's
    # rig52: the other arm is kept from the probe's uncertain stretch, not from the whole claim (which is gone);
    # its 1 mm move (its tip 14 mm or more from the probe's) was refused here before rig52, and goes now
    guard = guard_for(store, rig, "other")
    assert "its joint 3 is in flight or uncertain" in guard.unknown["probe"]
    assert guard.swept["probe"][2] == (lo, hi)
    assert [guard.swept["probe"][j] for j in (0, 1)] == [(kept.positions[j], kept.positions[j]) for j in (1, 2)]
    assert arm_move(store, rig, "other", by=1e-3).outcome.error is None


def test_a_jog_stops_when_another_arm_starts_to_move() -> None:
    # a jog's guard was the other arms as kept when the session began: a move of another arm started during the
    # session was never seen. Each tick with steps to send now reads them again (Guard.fresh).
    import math

    from stickslip.procedures.jog import JogController
    from stickslip.rig.guard import Guard
    from stickslip.rig.model import Rig as RigModel
    from test_envelope import mm3a
    from test_reach import CAL

    rig1 = RigModel("r", "r", (mm3a(),), ())
    now = [Guard(rig1, "a")]
    c = JogController(CAL, [0.0, -math.pi / 2, 0.002], speed_index=4, hold=0.0,
                      guard=Guard(rig1, "a", fresh=lambda: now[0]))
    c.press("a", 0.0)  # -x: joint 3 in
    moved, t = [], 0.0
    for k in range(40):
        if k == 20:  # the other arm's move claims its range
            now[0] = Guard(rig1, "a", unknown={"b": "a move of it claims its joint 3 between 0 µm and 9000 µm"})
        steps = c.tick(t, 0.05)
        moved.append(sum(abs(n) for n in steps))
        for j, n in enumerate(steps, start=1):
            if n:
                c.sent_steps(j, n)
        t += 0.05
    assert sum(moved[:20]) > 0 and sum(moved[20:]) == 0
    assert c.direction is None and c.message == "stopped at the rig's envelope (arm b): move another way"


@pytest.mark.parametrize(("claim", "kept"), [
    ([0.0, 1e300], (0.0, 0.012)),  # past the stop: the whole range, not a box 1e300 m wide
    ([-1e300, 1e300], (0.0, 0.012)),
    ([0.02, 0.03], (0.0, 0.012)),  # wholly past it: not a point at the stop
    ([0.009, 0.0], (0.0, 0.009)),  # high to low: in order
])
def test_a_hand_edited_claim_is_kept_within_the_joints_stops(rig: Rig, tmp_path: Path, claim: list[float],
                                                             kept: tuple[float, float]) -> None:
    # before audit55 a claim of [0, 1e300] m was used as it was: the refusal named a distance of 300 digits
    store = Store.open(tmp_path / "rig.db")
    key, specs = rig.state_key("other"), rig.arm("other").joint_specs()
    raw = load_state(store, key, specs).to_json() | {"claim": {"3": claim}}
    store.set_state(key, "positions", raw)
    assert load_state(store, key, specs).claim == {3: kept}
    guard = guard_for(store, rig, "probe")
    with pytest.raises(MoveRefused) as e:
        arm_move(store, rig, "probe")
    assert "claims its joint 3 between" in str(e.value) and "e+" not in str(e.value), str(e.value)
    assert guard.swept["other"][2] == kept
    store.close()


def test_a_rig_stop_that_cannot_be_read_mid_move_stops_it_exact_not_as_a_driver_failure(
    rig: Rig, tmp_path: Path
) -> None:
    # the rig's STOP is read from the store before each burst, inside the controller's step: a store that cannot
    # be read there (SQLite's "database is locked" under several arms' processes) is not the driver failing
    # (procedures.move.DRIVER_FAILURES: 'the device's driver failed', the joint uncertain over a burst never
    # sent); no further burst is sent, the position kept exact, as for a STOP record that is unreadable
    from stickslip.procedures import rigstop
    from stickslip.storage.schema import StoreError

    inner = Store.open(tmp_path / "rig.db")
    reads = {"n": 0}

    class LockedAtTheThirdRead:
        def get_state(self, device: str, key: str, default: Any = None) -> Any:
            if device.startswith("rig://stop/"):
                reads["n"] += 1
                if reads["n"] == 3:  # begin, burst 1: read; burst 2: locked
                    raise StoreError("database is locked")
            return inner.get_state(device, key, default)

        def __getattr__(self, name: str) -> Any:
            return getattr(inner, name)

    store: Any = LockedAtTheThirdRead()
    a = rig.arm("probe")
    request = MoveRequest(URLS["probe"], 3, by=3e-3, burst=500, guard=guard_for(inner, rig, "probe"),
                          joints=a.joint_specs(), state_key=rig.state_key("probe"))
    opener = rigstop.stoppable(opener_for(rig, "probe"), store, rig, "probe")
    r = move(store, request, true_calibration(URLS["probe"]), opener=opener)
    assert r.outcome.bursts == [500] and abs(r.plan.steps) > 1000
    assert r.outcome.error is not None and "driver" not in r.outcome.error
    assert "the rig's STOP could not be read (database is locked)" in r.outcome.error
    kept = load_state(inner, rig.state_key("probe"), a.joint_specs())
    assert not kept.uncertain and not kept.claim and kept.positions[3] == r.plan.position_after(500)
