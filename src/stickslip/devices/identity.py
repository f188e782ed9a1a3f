"""Which controller answers at a device URL, kept beside the positions kept for it.

The positions of :mod:`stickslip.devices.positions` are dead reckoned per device URL. When two
controllers swap URLs (two SmarAct MCS2s on a DHCP network swap addresses; ``/dev/ttyUSB0`` and
``/dev/ttyUSB1`` swap after a reboot), the next move would plan from the *other* arm's kept
position: silently wrong. A controller that can tell which one it is fills
:attr:`stickslip.devices.base.DeviceInfo.identity` (the MCS2's serial number, the MCS's system id,
the simulator's seed); :func:`open_checked` compares it, at every opening a procedure makes, with the
one kept under the state key :data:`IDENTITY_KEY` beside the positions (its own key: a move's
:func:`~stickslip.devices.positions.save_state` never overwrites it):

* nothing kept (a first opening, or a store written before identities were kept): kept, silently;
* the same: nothing said;
* another: every joint of the positions in hand is marked uncertain over its whole range ("another
  controller answers at this URL"), the new identity kept, the device closed and
  :class:`ControllerChanged` raised, its one line saying what was found and how to go on; nothing is
  sent to the device.

A controller that cannot tell (``identity is None``: the ANC300, the NanoControl) is not compared.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from typing import Any

from .base import Controller, DeviceError, command_url, redact_text, redact_url
from .positions import DeviceState, StateStore, save_state

__all__ = [
    "IDENTITY_KEY", "SWAPPED", "ControllerChanged", "check_controller", "kept_identity", "open_checked",
    "shown_identity",
]

IDENTITY_KEY = "controller"
"""The state key the controller's identity is kept under, beside ``positions``."""

IDENTITY_VERSION = 1

SWAPPED = "another controller answers at this URL"
"""Why a joint is uncertain after its URL reached another controller (:meth:`DeviceState.mark_uncertain`)."""


class ControllerChanged(DeviceError):
    """Another controller answers at a device URL than the one its positions were kept for; nothing was sent."""


SHOWN_CHARS = 120
"""At most this many characters of an identity are kept as its text and said in a message (a controller may answer
anything: 10 kB of it made a 20 kB line); the comparison is of the whole identity's digest."""


def shown_identity(identity: str) -> str:
    """``identity`` as it is kept and said: one printable line (a NUL, a line break, a lone surrogate as ``?``),
    through the store's own redaction (:func:`~stickslip.devices.base.redact_text`: what it keeps of
    ``token=...`` or ``user:...@``), at most :data:`SHOWN_CHARS` characters."""
    text = redact_text("".join(c if c.isprintable() else "?" for c in identity))
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS - 1] + "\u2026"


def _digest(identity: str) -> str:
    return hashlib.sha256(identity.encode("utf-8", "surrogatepass")).hexdigest()


def _kept(store: StateStore, key: str) -> tuple[str, str | None] | None:
    """The kept identity's text and digest (``None``: a row written before digests, compared by its text); ``None``
    for none, or a row that is not one: of another type, or not JSON at all (a hand edit, a bad sector: its error
    refused every move of the controller, and nothing wrote the row again). Such a row is kept again at this
    opening, as a first one is: a swap at the same time goes unseen (cannot tell)."""
    try:
        raw: Any = store.get_state(key, IDENTITY_KEY)
    except (OSError, ValueError):
        return None
    if not (isinstance(raw, dict) and isinstance(raw.get("identity"), str) and raw["identity"]):
        return None
    digest = raw.get("sha256")
    return str(raw["identity"]), digest if isinstance(digest, str) and digest else None


def kept_identity(store: StateStore, key: str) -> str | None:
    """The identity kept for the positions under ``key`` (:func:`shown_identity`); ``None`` if none is (or it is not
    readable as one)."""
    kept = _kept(store, key)
    return None if kept is None else kept[0]


def _same(kept: tuple[str, str | None], identity: str) -> bool:
    text, digest = kept
    return digest == _digest(identity) if digest is not None else text == shown_identity(identity)


def _keep(store: StateStore, key: str, identity: str) -> None:
    """Keep ``identity`` as its text (:func:`shown_identity`: the store redacts what it keeps, so the text alone
    differed from the identity at every opening) and the digest it is compared by."""
    store.set_state(key, IDENTITY_KEY, {"version": IDENTITY_VERSION, "identity": shown_identity(identity),
                                        "sha256": _digest(identity)})


def check_controller(store: StateStore, url: str, dev: Controller, states: Sequence[DeviceState]) -> None:
    """Compare ``dev``'s identity with the one kept for each of ``states`` (the positions the caller holds, then
    those of the rig's other arms on this controller: their positions too were kept for the one it was).

    A first opening keeps it; another one marks every joint of that state uncertain over its whole range
    (saved, and in memory: a later save of ``state`` keeps the marks), keeps the new identity, and raises
    :class:`ControllerChanged`. The marks are written before the identity: a store that fails between the two
    leaves the old identity kept, and the next opening finds the swap again.
    """
    identity = getattr(getattr(dev, "info", None), "identity", None)  # a wrapper or a fake may tell no info
    if not isinstance(identity, str) or not identity:
        return
    changed: list[tuple[DeviceState, str]] = []
    for state in states:
        kept = _kept(store, state.device)
        if kept is not None and _same(kept, identity):
            continue
        if kept is not None:
            for joint in sorted(state.positions):
                spec = state.spec(joint)
                state.mark_uncertain(joint, spec.lower, spec.upper, SWAPPED)
            save_state(store, state)
            changed.append((state, shown_identity(kept[0])))  # a row kept before, or edited by hand
        _keep(store, state.device, identity)
    if changed:
        state, kept_text = changed[0]
        _, arm_tag, arm = state.device.partition("#arm=")  # a rig's arm sharing its controller: its own key
        where = f"--rig RIG --arm {arm}" if arm_tag else f"-d {command_url(url)}"
        raise ControllerChanged(
            f"another controller answers at {redact_url(url)}: {shown_identity(identity)}, where the positions were "
            f"kept for {kept_text}; nothing was sent, and every joint of "
            f"{' and of '.join(redact_url(st.device) for st, _ in changed)} is now uncertain over its whole range: "
            f"re-reference each at an end stop (`stickslip where {where} --set J=min` after "
            "driving joint J to its lower stop), or open the URL that reaches the other controller"
        )


def open_checked(
    store: StateStore, url: str, opener: Callable[[str], Controller], *states: DeviceState
) -> Controller:
    """``opener(url)``, its identity checked against the one kept for ``states`` (:func:`check_controller`).

    On :class:`ControllerChanged` (or any failure of the check) the device is closed before the error
    goes on: nothing was sent to it.
    """
    dev = opener(url)
    try:
        check_controller(store, url, dev, states)
    except BaseException:
        try:
            dev.close()
        except DeviceError:
            pass
        raise
    return dev
