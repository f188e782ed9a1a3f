"""Where a device's joints are kept, and putting them somewhere known: the workflow behind ``stickslip where``.

:func:`where` reads the kept state of a device (positions, how each is known, the base
tilt, the Kalman track of each joint), records a pose or a reference first if asked
(a joint put at a known point, e.g. an end stop), and asks the device whether it
answers (:func:`probe_device`) unless told not to.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from typing import Any, Protocol
from urllib.parse import urlsplit

from ..devices.base import DeviceError, controller_of, device_key, open_device
from ..devices.positions import DeviceState, StateStore, UnreadableState, load_state, save_state
from ..joints import JointSet
from ..processes import holder_running, process_gone
from ..units import format_position
from .move import DeviceBusy, LockStore, PoseUpdate, device_lock, holder_text, track_fields

__all__ = [
    "DeviceUnreachable", "ReferenceRefused", "WhereResult", "WhereStore", "port_order_warning", "probe_device",
    "state_rows", "where",
]


class DeviceUnreachable(DeviceError):
    """The device could not be opened or did not answer (the message says why and how to go on)."""


class ReferenceRefused(ValueError):
    """A reference (``joint``, ``q``) cannot be kept: ``index`` is its place in the list given."""

    def __init__(self, index: int, message: str):
        super().__init__(message)
        self.index = index


class WhereStore(StateStore, LockStore, Protocol):
    """What :func:`where` needs of a store (``stickslip.storage.Store`` implements it)."""


_ENUMERATED_PORT = re.compile(r"/dev/(tty(?:USB|ACM)\d+|cu\.usb\S*)$")
"""A serial port named by the order the adapters were found (Linux ``ttyUSBn``/``ttyACMn``, a Mac's ``cu.usb...``)."""


def port_order_warning(url: str) -> str | None:
    """The line that says ``url``'s serial port is named by the order adapters were found, and what to write
    instead; ``None`` for any other URL (a ``/dev/serial/by-id/`` link, a network address, ``COM3``).

    Two adapters may swap ``/dev/ttyUSB0`` and ``/dev/ttyUSB1`` after a reboot: the positions kept for this
    URL would be the other arm's. A SmarAct MCS says which controller it is (checked at every opening:
    :mod:`stickslip.devices.identity`); an MM3A's NanoControl or an ANC300 cannot, so only the name can.
    """
    try:
        path = urlsplit(device_key(url)).path
    except ValueError:
        return None
    m = _ENUMERATED_PORT.search(path)
    if m is None:
        return None
    return (
        f"{m.group(0)} is named by the order the USB adapters were found: after a reboot it may reach another "
        "controller, and its positions would be the other arm's (a NanoControl or an ANC300 cannot say which it "
        "is); write the port as its stable link, e.g. /dev/serial/by-id/usb-FTDI_..._A1B2C3-if00-port0 "
        "(`ls -l /dev/serial/by-id/` shows which), and reference the joints under that URL"
    )


def probe_device(url: str, opener: Callable[[str], Any] = open_device) -> dict[str, Any]:
    """Open ``url`` and close it again: what it says about itself; :class:`DeviceUnreachable` if it does not answer.

    A URL whose options the driver refuses raises its ``ValueError`` as it is (nothing was asked).

    ``{"model": ..., **info.extra}``: for a NanoControl the dialect, firmware version,
    stepping frequencies and active speed profile (docs/devices/nanocontrol.md).
    """
    hint = "(use --offline to see the kept positions only)"
    try:
        dev = opener(url)  # a ValueError here is the URL's options (axes=1,1,2, timeout=nan): not the device's silence
    except (DeviceError, OSError) as e:
        raise DeviceUnreachable(f"the device does not answer: {e} {hint}") from None
    try:
        info = dev.info
        return {"model": str(info.model), **{str(k): v for k, v in info.extra.items()}}
    except (DeviceError, ValueError, OSError) as e:
        raise DeviceUnreachable(f"the device does not answer: {e} {hint}") from None
    finally:
        try:
            dev.close()
        except (DeviceError, OSError):
            pass


def state_rows(state: DeviceState) -> list[dict[str, object]]:
    """One row per joint (SI): position, unit, display text, source, uncertain bounds, ``sd`` and step scale."""
    rows: list[dict[str, object]] = []
    for j in (1, 2, 3):
        rows.append(
            {
                "joint": j,
                "q": state.positions[j],
                "unit": state.spec(j).unit,
                "display": format_position(state.positions[j], state.spec(j)),
                "source": "uncertain" if j in state.uncertain else state.sources[j],
                "uncertain": list(state.uncertain[j]) if j in state.uncertain else None,
                **track_fields(state, j),
            }
        )
    return rows


@dataclass(frozen=True)
class WhereResult:
    """What :func:`where` found (SI units).

    Attributes
    ----------
    device : str
        The name the device's state is kept under: its controller (:func:`~stickslip.devices.base.controller_of`:
        the URL without options or secrets, the default port written out), or a rig arm's key.
    state : DeviceState
        The kept state (after any reference or pose recorded).
    changed : tuple of str
        What was recorded (``"q3"``, ``"theta"``, ...).
    info : dict or None
        What the device said about itself (``model`` and more), ``None`` if it was not asked.
    busy : str or None
        Why the device was not asked: another process drives it (the :class:`~.move.DeviceBusy` message).
    replaced : str or None
        Why the kept positions were replaced by the defaults before recording (they could not be read:
        :class:`~stickslip.devices.positions.UnreadableState`); ``None`` when they were read.
    """

    device: str
    state: DeviceState
    changed: tuple[str, ...] = ()
    info: dict[str, Any] | None = field(default=None)
    busy: str | None = None
    replaced: str | None = None

    def as_dict(self) -> dict[str, object]:
        """The JSON shape of ``stickslip where --json``."""
        s = self.state
        answers = self.info["model"] if self.info else None
        return {
            "device": self.device, "joints": state_rows(s), "theta": s.theta, "psi": s.psi, "answers": answers,
            "info": self.info, "busy": self.busy,
        }


def where(
    store: WhereStore,
    device: str,
    *,
    references: Sequence[tuple[int, float]] = (),
    pose: PoseUpdate = PoseUpdate(),
    offline: bool = False,
    unlock: bool = False,
    probe: Callable[[str], dict[str, Any]] = probe_device,
    joints: JointSet | None = None,
    key: str | None = None,
    hold_lock: bool = False,
) -> WhereResult:
    """The kept state of ``device``, after recording ``pose`` and ``references`` (``(joint, q)``, rad or m).

    A reference puts a joint at a known point (an end stop, a measured position): its
    source becomes ``"set"`` and an interrupted move's uncertainty is cleared. Without
    anything recorded and unless ``offline``, the device is asked whether it answers
    (:func:`probe_device`; :class:`DeviceUnreachable`), unless another process holds its
    lock (``busy`` says who). ``unlock`` releases a lock left by
    a process that is gone (:class:`~.move.DeviceBusy` if it is running on this host).
    :class:`ReferenceRefused` names a reference that cannot be kept.
    ``joints``: the arm's joints (a rig file's arm: :meth:`stickslip.rig.Arm.joint_specs`),
    the MM3A's by default; ``key`` where they are kept (:meth:`stickslip.rig.Rig.state_key`:
    two arms on one controller), the device's key by default. ``hold_lock``: record under the
    device's lock (:func:`~.move.device_lock`; :class:`~.move.DeviceBusy` while another
    process drives the device), as a command does; the server, which holds the lock, does not.
    """
    lock = controller_of(device)  # the name its rows are kept and its lock taken under, however its URL is written
    key = key or lock
    if unlock:
        try:
            holder = store.get_state(lock, "lock")
        except (OSError, ValueError):  # a row that cannot be read (not JSON: a hand edit, a bad sector) names no
            holder = None  # running holder; it refused every move of the controller, and --unlock is the way out
        refuse_unlocking_a_running_holder(holder, lock)
        store.set_state(lock, "lock", "null")
    records = bool(references) or pose != PoseUpdate()
    held: AbstractContextManager[object] = device_lock(store, lock) if hold_lock and records else nullcontext()
    replaced = None
    with held:  # a joint referenced while another process moves it would be kept where it no longer is
        try:
            state = load_state(store, key, joints)
        except UnreadableState as e:  # no command could read them: recording positions anew is the way out
            if not records:
                raise
            state, replaced = DeviceState.default(key, joints), e.what
        changed = pose.apply(state)
        for i, (joint, q) in enumerate(references):
            try:
                state.set_position(joint, q, "set")
            except ValueError as e:
                raise ReferenceRefused(i, str(e)) from None
            changed.append(f"q{joint}")
        if changed:
            save_state(store, state)
    info, busy = None, None
    if not (changed or offline):
        busy = _driven_by(store.get_state(lock, "lock"), lock)
        if busy is None:  # a probe beside a move would talk on the link the move is driving
            info = probe(device)
    return WhereResult(key, state, tuple(changed), info, busy, replaced)


def _driven_by(holder: object, lock: str) -> str | None:
    """Who holds ``lock`` (read, not taken: a read-only database still shows), ``None`` if nobody or a process gone."""
    if not isinstance(holder, dict) or process_gone(holder):
        return None
    return f"{lock} is being driven by another stickslip process ({holder_text(holder)})"


def refuse_unlocking_a_running_holder(holder: object, device: str) -> None:
    """:class:`~.move.DeviceBusy` if the lock's ``holder`` is a process running on this host.

    ``--unlock`` is for a lock whose process is gone; one that runs here (a ``move``, or
    ``stickslip serve`` holding the device) keeps it: unlocking it let a second process
    drive the device while the first still did. A holder that is gone is taken over
    without ``--unlock``; one on another host, or not known to run (its number reused
    after a restart: :func:`~stickslip.processes.holder_running`), is the user's to release.
    """
    if not holder_running(holder) or not isinstance(holder, dict):
        return
    raise DeviceBusy(
        f"{device} is locked by pid {holder.get('pid')} on this computer ({holder.get('host')}, since "
        f"{holder.get('since')}), which is still running: --unlock is for a lock whose process is gone; "
        "stop that process (Ctrl-C in its terminal), and its lock goes with it"
    )
