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
from stickslip.devices.positions import load_state  # noqa: E402
from stickslip.procedures.arms import guard_for  # noqa: E402
from stickslip.procedures.move import MoveRefused  # noqa: E402
from stickslip.rig import Rig, load_rig  # noqa: E402
from stickslip.storage import Store  # noqa: E402
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
            if device == rig.state_key("other"):
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
