"""Drive a served rig from Python: the verbs of ``stickslip serve``'s API, for scripts and notebooks.

::

    from stickslip.client import Rig

    with Rig("http://127.0.0.1:8765") as rig:          # token="..." for a server on another address
        print(rig.where()["joints"])
        rig.move(3, by="30um")                          # waits until the move ends; MotionFailed if it did not
        rig.save_position("above the cell")
        rig.reach(by=("0um", "0um", "-10um"))
        rig.go_to("above the cell")
        rig.stop()                                      # every axis, now

Amounts are SI as numbers (m, rad) or strings with their unit (``"30um"``, ``"2deg"``),
as on the command line. A motion call waits for its end unless ``wait=False`` (then it
returns the motion at once; :meth:`Rig.wait` waits for it); Ctrl-C (KeyboardInterrupt)
while waiting sends STOP. Errors: :class:`RigError` with the server's one line and its
HTTP status (a refusal before anything moved), :class:`MotionFailed` for a motion that
ended without completing (stopped, or a device error; the kept positions are honest).

Needs ``httpx`` (``pip install 'stickslip[client]'``); :meth:`Rig.live` also ``websockets``.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator, Sequence
from types import TracebackType
from typing import Any

__all__ = ["MotionFailed", "Rig", "RigError"]

Amount = float | str
"""SI (m or rad) as a number, or a string with its unit."""


def _plain(name: str, value: Any) -> Any:
    """``value`` as JSON the server reads: numpy scalars and 0-d arrays as Python numbers, lists and dicts inside.

    A NaN or infinite number is a ValueError naming the argument, a value JSON cannot carry a
    TypeError naming it (both before anything is sent).
    """
    if getattr(value, "shape", None) == () and hasattr(value, "item"):
        value = value.item()  # numpy.float64(1e-6), numpy.int64(3), numpy.array(1e-6)
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{name}: {value} is not a finite number")
    if isinstance(value, dict):
        return {k: _plain(f"{name}.{k}" if name else str(k), v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(f"{name}[{i}]", v) for i, v in enumerate(value)]
    if value is None or isinstance(value, (str, int, float)):
        return value
    raise TypeError(f"{name}: a number or a string with its unit, got {type(value).__name__} {value!r}")


class RigError(RuntimeError):
    """The server refused a request (``status``: its HTTP status) or could not be reached (``status`` 0)."""

    def __init__(self, message: str, status: int = 0):
        super().__init__(message)
        self.status = status


class MotionFailed(RigError):
    """A motion ended without completing: ``motion`` is its record (status ``stopped`` or ``failed``, the error)."""

    def __init__(self, motion: dict[str, Any]):
        super().__init__(f"{motion.get('what')}: {motion.get('status')}: {motion.get('error')}", 200)
        self.motion = motion


class Rig:
    """A client of one ``stickslip serve``.

    Parameters
    ----------
    url : str
        The server's address, ``http://host:port``.
    token : str, optional
        The server's token (needed when it listens on an address other than loopback).
    timeout : float
        Seconds to wait for an answer to one request.
    """

    def __init__(self, url: str = "http://127.0.0.1:8765", token: str | None = None, timeout: float = 35.0):
        import httpx

        self.url = url.rstrip("/")
        self._token = token
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self._http = httpx.Client(base_url=self.url, headers=headers, timeout=timeout)

    def __repr__(self) -> str:
        return f"Rig({self.url!r})"

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, t: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection."""
        self._http.close()

    # ------------------------------------------------------------ requests

    def _call(self, method: str, path: str, body: dict[str, Any] | None = None, **params: Any) -> Any:
        import httpx

        body = None if body is None else _plain("", body)
        try:
            r = self._http.request(method, path, json=body, params=params or None)
        except httpx.HTTPError as e:
            raise RigError(f"{self.url}: {e}") from None
        try:
            data = r.json()
        except ValueError:
            data = None
        if r.status_code >= 400:
            message = data.get("error") if isinstance(data, dict) else None
            raise RigError(message or f"HTTP {r.status_code}", r.status_code)
        if data is None and r.content:
            raise RigError(f"{self.url}: {method} {path} answered with what is not JSON (not a stickslip server?)")
        return data

    def _motion(self, path: str, body: dict[str, Any] | None, wait: bool, timeout: float | None) -> dict[str, Any]:
        m: dict[str, Any] = _motion_record(self._call("POST", path, body), path)
        return self.wait(int(m["id"]), timeout) if wait else m

    def wait(self, motion: int, timeout: float | None = None) -> dict[str, Any]:
        """Wait for motion ``motion`` to end; its record. :class:`MotionFailed` if it did not complete.

        Ctrl-C while waiting sends STOP (and raises ``KeyboardInterrupt``). ``timeout`` (s):
        :class:`RigError` if it has not ended by then (it goes on running).
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        try:
            while True:
                left = 25.0 if deadline is None else min(25.0, deadline - time.monotonic())
                if left <= 0:
                    raise RigError(f"motion {motion} has not ended after {timeout} s (it goes on; rig.stop() ends it)")
                m = _motion_record(self._call("GET", f"/api/motions/{motion}", wait=round(left, 3)), "/api/motions")
                if m["status"] not in ("starting", "running"):
                    if m["status"] in ("failed", "stopped", "refused"):
                        raise MotionFailed(m)
                    return m
        except KeyboardInterrupt:
            self.stop()
            raise

    # ------------------------------------------------------------ the verbs

    def state(self) -> dict[str, Any]:
        """The live state once: joints ± sd, tip ± sd, the motion, jog, the calibration day (SI)."""
        return dict(self._call("GET", "/api/state"))

    def where(self) -> dict[str, Any]:
        """The kept positions (the shape of ``stickslip where --json``)."""
        return dict(self._call("GET", "/api/where"))

    def reference(self, joint: int, q: Amount) -> dict[str, Any]:
        """Record that ``joint`` is at ``q`` (a position, or ``"min"``/``"max"``: an end stop)."""
        return dict(self._call("POST", "/api/where", {"set": {str(joint): q}}))

    def move(
        self, joint: int, by: Amount | None = None, to: Amount | None = None, wait: bool = True,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """Move ``joint`` by or to an amount (``stickslip move``); the motion's record (its ``result`` when done)."""
        body: dict[str, Any] = {"joint": joint}
        if by is not None:
            body["by"] = by
        if to is not None:
            body["to"] = to
        return self._motion("/api/move", body, wait, timeout)

    def step(self, joint: int, steps: int, wait: bool = True, timeout: float | None = None) -> dict[str, Any]:
        """Raw steps, no calibration (the joint is then uncertain until referenced)."""
        return self._motion("/api/step", {"joint": joint, "steps": steps}, wait, timeout)

    def reach(
        self, to: Sequence[Amount] | None = None, by: Sequence[Amount] | None = None, wait: bool = True,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """Move the tip in a straight line to or by a point (three lengths, base frame)."""
        body = {"to": list(to)} if to is not None else {"by": list(by or ())}
        return self._motion("/api/reach", body, wait, timeout)

    def stop(self) -> dict[str, Any]:
        """STOP: every axis, now."""
        return dict(self._call("POST", "/api/stop"))

    def jog(self, direction: str, seconds: float, speed: int | None = None) -> dict[str, Any]:
        """Jog the tip along ``direction`` (``"+x"`` ... ``"-z"``) for ``seconds``, then let go.

        Holds the direction with a keep-alive every 50 ms (the server's dead man's switch
        stops the tip within 0.3 s of the last), so a script that dies stops the arm.
        ``speed``: preset 1-7 (0.1 to 100 µm/s). Returns the jog session's record once it has
        ended (what was sent per joint).
        """
        seconds = _plain("seconds", seconds)
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or seconds < 0:
            raise ValueError(f"seconds: how long to hold the direction, 0 s or more, got {seconds!r}")
        end = time.monotonic() + float(seconds)
        body: dict[str, Any] = {"direction": direction}
        if speed is not None:
            body["speed"] = speed
        released: dict[str, Any] = {}
        try:
            self._call("POST", "/api/jog", body)
            while time.monotonic() < end:
                time.sleep(min(0.05, max(0.0, end - time.monotonic())))
                self._call("POST", "/api/jog", body)
        finally:
            released = self._call("POST", "/api/jog/release", end="true")
        return self.wait(int(released["motion"])) if "motion" in released else released

    def observe(
        self, joint: int, q: Amount, sd: Amount | None = None, at_stop: bool = False, force: bool = False
    ) -> dict[str, Any]:
        """A measured position of ``joint`` into its track (``stickslip observe``)."""
        body: dict[str, Any] = {"joint": joint, "q": q, "at_stop": at_stop, "force": force}
        if sd is not None:
            body["sd"] = sd
        return dict(self._call("POST", "/api/observe", body))

    def traverse(self, joint: int, direction: str, wait: bool = True, timeout: float | None = None) -> dict[str, Any]:
        """One traverse from stop to stop, timed by the limit switch, stored."""
        return self._motion("/api/traverse", {"joint": joint, "direction": direction}, wait, timeout)

    def positions(self) -> list[dict[str, Any]]:
        """The named positions."""
        return list(self._call("GET", "/api/positions")["positions"])

    def save_position(self, name: str) -> dict[str, Any]:
        """Keep the current positions under ``name``."""
        return dict(self._call("POST", "/api/positions", {"name": name}))

    def delete_position(self, name: str) -> None:
        """Forget the named position ``name``."""
        self._call("DELETE", f"/api/positions/{name}")

    def go_to(self, name: str, wait: bool = True, timeout: float | None = None) -> dict[str, Any]:
        """Drive back to the named position ``name``."""
        return self._motion(f"/api/positions/{name}/go", None, wait, timeout)

    def calibration_day(
        self, day: str | None = None, resume: bool = False, wait: bool = False, timeout: float | None = None
    ) -> dict[str, Any]:
        """Start (or resume) the calibration day; by default returns at once (follow it with :meth:`day`)."""
        body: dict[str, Any] = {"resume": resume}
        if day is not None:
            body["day"] = day
        return self._motion("/api/day", body, wait, timeout)

    def day(self) -> dict[str, Any]:
        """The calibration day's plan, progress and result."""
        return dict(self._call("GET", "/api/day"))

    def calibration(self) -> dict[str, Any]:
        """The calibration in use: parameters with standard errors, its report."""
        return dict(self._call("GET", "/api/calibration"))

    def live(self, messages: int | None = None) -> Iterator[dict[str, Any]]:
        """The live state as it comes (20 a second): ``{"seq", "run", "t", "state", "events"}``; ``messages`` then stop.

        ``run`` names the server's run (another after a restart, its event ids from 1 again).
        """
        from websockets.sync.client import connect

        if messages is not None and (isinstance(messages, bool) or _plain("messages", messages) < 0):
            raise ValueError(f"messages: how many messages to take, 0 or more (None: until closed), got {messages!r}")
        ws_url = "ws" + self.url[len("http"):] + "/api/live"
        headers = {"Authorization": f"Bearer {self._token}"} if self._token else None
        with connect(ws_url, additional_headers=headers) as ws:
            n = 0
            while messages is None or n < messages:
                m = json.loads(ws.recv())
                if "seq" in m:
                    n += 1
                    yield m


def _motion_record(data: object, path: str) -> dict[str, Any]:
    """``data`` as a motion's record (an integer ``id`` and a ``status``); :class:`RigError` if it is not one."""
    if (
        not isinstance(data, dict) or not isinstance(data.get("id"), int) or isinstance(data.get("id"), bool)
        or not isinstance(data.get("status"), str)
    ):
        raise RigError(f"{path} answered {str(data)[:80]!r}, not a motion's record (not a stickslip server?)")
    return data
