"""Independent SmarAct MCS and MCS2 controllers on loopback TCP ports, for the tests.

Written from docs/devices/smaract.md alone, sharing no code with
``stickslip.sim.smaract_emulator`` or the driver. It moves no arm: it counts, per channel,
the steps each burst made, so tests compare them with what ``stickslip plan`` says.

* A burst of ``n`` steps at ``f`` Hz started at ``t0`` makes its steps at the instants
  ``t0 + k / f`` (k = 0 .. |n|-1) and steps until ``t0 + |n| / f``; a stop at ``t`` has
  made the steps whose instants came before ``t``.
* MCS: a command is ``:`` + text + LF; answers are ``:`` + text + LF. ``:SCM0`` ->
  ``:E-1,0``; ``:GNC`` -> ``:N<count>``; ``:GSI`` -> ``:ID<id>``; ``:GIV`` -> ``:IV..``;
  ``:MST<ch>,<n>,<a>,<f>`` -> ``:E<ch>,0``; ``:GS<ch>`` -> ``:S<ch>,<1 stepping | 0>``;
  ``:S<ch>`` -> ``:E<ch>,0``.
* MCS2: a command ends in CR LF; queries (``?``) get one line ending in CR LF, nothing
  else is answered; errors are queued (``:SYST:ERR:COUN?``, ``:SYST:ERR?``). ``:MOVE``
  needs ``:MMOD 4`` first; ``:STAT?`` sets bit 0x0001 while stepping (and always 0x40000,
  a bit the driver must ignore).

Anything outside those forms (a 0 or +-30000 step count, amplitude 0, a frequency out of
range, a bare LF on the MCS2, a CR on the MCS) is kept in :attr:`SmarActPeer.violations`.

Faults (``fault=``): ``"refuse"`` refuses every burst command (MCS ``:E<ch>,150``; MCS2
error -300 queued); ``"mute"`` carries out the first burst command and answers nothing
from then on; ``"endless"`` makes bursts that never end by themselves.
"""

from __future__ import annotations

import math
import re
import socket
import threading
import time


class SmarActPeer:
    """``kind`` is ``"mcs"`` or ``"mcs2"``; ``channels`` the number of channels it has."""

    def __init__(self, kind: str, fault: str | None = None, channels: int = 4) -> None:
        assert kind in ("mcs", "mcs2")
        self.kind = kind
        self.fault = fault
        self.n_channels = channels
        self.log: list[str] = []
        self.violations: list[str] = []
        self.steps = dict.fromkeys(range(channels), 0)
        self.mute = False
        self.queue: list[tuple[int, str]] = []
        self.mode = dict.fromkeys(range(channels), 0)
        self.freq = dict.fromkeys(range(channels), 500)
        self.ampl = dict.fromkeys(range(channels), 30000)
        self._bursts: dict[int, tuple[float, int, float]] = {}  # channel -> (t0, n, f)
        self._end = threading.Event()
        self._server = socket.create_server(("127.0.0.1", 0))
        self.port = self._server.getsockname()[1]
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def url(self) -> str:
        scheme = "smaract-mcs+socket" if self.kind == "mcs" else "smaract-mcs2"
        return f"{scheme}://127.0.0.1:{self.port}"

    @property
    def name(self) -> str:
        return f"127.0.0.1:{self.port}"

    def stepping(self) -> list[int]:
        now = time.monotonic()
        return [c for c, (t0, n, f) in self._bursts.items() if self._running(t0, n, f, now)]

    def __enter__(self) -> SmarActPeer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._end.set()
        self._thread.join(timeout=2)
        self._server.close()

    # -- steps --------------------------------------------------------------------------
    def _running(self, t0: float, n: int, f: float, t: float) -> bool:
        return self.fault == "endless" or t < t0 + abs(n) / f

    def _halt(self, ch: int, t: float) -> None:
        if ch not in self._bursts:
            return
        t0, n, f = self._bursts.pop(ch)
        made = min(abs(n), max(0, math.ceil((t - t0) * f)))
        self.steps[ch] += made if n > 0 else -made

    def _begin(self, ch: int, n: int, f: float, t: float) -> None:
        self._halt(ch, t)
        self._bursts[ch] = (t, n, f)

    def _tick(self, t: float) -> None:
        for ch in list(self._bursts):
            t0, n, f = self._bursts[ch]
            if not self._running(t0, n, f, t):
                self._halt(ch, t)

    # -- the line -----------------------------------------------------------------------
    def _run(self) -> None:
        self._server.settimeout(0.05)
        while not self._end.is_set():
            try:
                conn, _ = self._server.accept()
            except OSError:
                continue
            with conn:
                conn.settimeout(0.02)
                pending = b""
                while not self._end.is_set():
                    try:
                        chunk = conn.recv(1024)
                    except TimeoutError:
                        continue
                    except OSError:
                        break
                    if not chunk:
                        break
                    pending += chunk
                    while b"\n" in pending:
                        line, _, pending = pending.partition(b"\n")
                        reply = self._one(line.decode("ascii", "replace"), time.monotonic())
                        if reply and not self.mute:
                            conn.sendall(reply.encode("ascii"))

    def _one(self, raw: str, t: float) -> str:
        self._tick(t)
        if self.kind == "mcs":
            if "\r" in raw:
                self.violations.append(f"CR in an MCS command: {raw!r}")
            text = raw.strip("\r")
            self.log.append(text)
            reply = self._mcs(text, t)
            return f":{reply}\n" if reply else ""
        if not raw.endswith("\r"):
            self.violations.append(f"MCS2 command not ended by CR LF: {raw!r}")
        text = raw.rstrip("\r")
        self.log.append(text)
        answer = self._mcs2(text, t)
        return f"{answer}\r\n" if answer is not None else ""

    # -- MCS ----------------------------------------------------------------------------
    def _mcs(self, text: str, t: float) -> str:
        if not text.startswith(":"):
            self.violations.append(f"no colon: {text!r}")
            return "E-1,1"
        body = text[1:]
        fixed = {"SCM0": "E-1,0", "GNC": f"N{self.n_channels}", "GSI": "ID77", "GIV": "IV1,2,3"}
        if body in fixed:
            return fixed[body]
        m = re.fullmatch(r"MST(\d+),(-?\d+),(\d+),(\d+)", body)
        if m:
            ch, n, a, f = (int(g) for g in m.groups())
            if ch >= self.n_channels:
                return "E-1,7"
            if n == 0 or abs(n) >= 30000 or not 1 <= a <= 4095 or not 1 <= f <= 18500:
                self.violations.append(f"burst outside the documented ranges: {text!r}")
            if self.fault == "refuse":
                return f"E{ch},150"
            self._begin(ch, n, f, t)
            if self.fault == "mute":
                self.mute = True
            return f"E{ch},0"
        m = re.fullmatch(r"(GS|S)(\d+)", body)
        if m and int(m.group(2)) < self.n_channels:
            ch = int(m.group(2))
            if m.group(1) == "S":
                self._halt(ch, t)
                return f"E{ch},0"
            return f"S{ch},{1 if ch in self._bursts else 0}"
        self.violations.append(f"not a documented command: {text!r}")
        return "E-1,2"

    # -- MCS2 ---------------------------------------------------------------------------
    def _mcs2(self, text: str, t: float) -> str | None:
        if text == ":SYST:ERR:COUN?":
            return str(len(self.queue))
        if text == ":SYST:ERR?":
            code, words = self.queue.pop(0) if self.queue else (0, "No error")
            return f'{code},"{words}"'
        if text == ":DEV:NOCH?":
            return str(self.n_channels)
        if text == ":DEV:SNUM?":
            return "PEER-0042"
        m = re.fullmatch(r":CHAN(\d+):(STAT\?|MMOD (\d+)|STEP:FREQ (\d+)|STEP:AMPL (\d+))", text)
        if m and int(m.group(1)) < self.n_channels:
            ch = int(m.group(1))
            if m.group(2) == "STAT?":
                return str(0x40000 | (1 if ch in self._bursts else 0))
            if m.group(3) is not None:
                self.mode[ch] = int(m.group(3))
            elif m.group(4) is not None:
                f = int(m.group(4))
                if not 1 <= f <= 20000:
                    self.violations.append(f"frequency out of range: {text!r}")
                self.freq[ch] = f
            else:
                a = int(m.group(5))
                if not 1 <= a <= 65535:
                    self.violations.append(f"amplitude out of range: {text!r}")
                self.ampl[ch] = a
            return None
        m = re.fullmatch(r":(MOVE|STOP)(\d+)(?: (-?\d+))?", text)
        if m and int(m.group(2)) < self.n_channels:
            ch = int(m.group(2))
            if m.group(1) == "STOP":
                self._halt(ch, t)
                return None
            n = int(m.group(3) or 0)
            if n == 0 or abs(n) > 100000:
                self.violations.append(f"burst outside the documented range: {text!r}")
            if self.mode[ch] != 4:
                self.violations.append(f"MOVE outside step mode: {text!r}")
                self.queue.append((259, "No sensor present"))
                return None
            if self.fault == "refuse":
                self.queue.append((-300, "Device-specific error"))
                return None
            self._begin(ch, n, self.freq[ch], t)
            if self.fault == "mute":
                self.mute = True
            return None
        self.violations.append(f"not a documented command: {text!r}")
        self.queue.append((-113, "Undefined header"))
        return None
