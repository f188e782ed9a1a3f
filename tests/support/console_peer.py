"""An independent NanoControl *console* on a pseudo-terminal, for the tests.

Written from the issue's description of the current console only, sharing no code with
``stickslip.sim.console_emulator`` or the driver:

* a command is ASCII ending in CR; a ``;`` or LF in it is a protocol violation (kept in
  :attr:`ConsolePeer.violations`, answered ``e``);
* every command except ``stopnack`` is answered by one line ``o<TAB>...<CR>`` (or
  ``e<TAB>...<CR>``); answers end in CR only;
* ``frequency fA fB fC fD`` (300..20000 Hz); every channel steps at 700 Hz at power-on;
* ``speed P vA vB vC vD`` / ``speed P`` / ``speed ?`` (six profiles, ``c16`` everywhere
  and profile 3 active at power-on);
* ``go mA mB mC mD T``: from the instant ``go`` is read, each channel makes its
  profile's count x |m| steps at its frequency every T ms. Steps are instants: those of
  an interval that starts at ``s`` fall at ``s + k/f`` (k = 0, 1, ...), and a halt at
  ``t`` has made those with ``s + k/f < t``. ``stop``, ``stopnack`` or another ``go``
  halts every channel.

Faults (``fault=``): ``"error"`` answers ``go`` with ``e`` (nothing drives); ``"silent"``
carries out ``go`` and everything after it but answers nothing more.
"""

from __future__ import annotations

import math
import os
import select
import threading
import time


class ConsolePeer:
    POWER_ON_HZ = 700

    def __init__(self, fault: str | None = None):
        self.fault = fault
        self.mute = False
        self.log: list[tuple[float, str]] = []
        self.violations: list[str] = []
        self.hz = dict.fromkeys("ABCD", self.POWER_ON_HZ)
        self.profiles = {p: ["c16"] * 4 for p in range(1, 7)}
        self.active = 3
        self.steps = dict.fromkeys("ABCD", 0)
        self.fine = dict.fromkeys("ABCD", 0)
        self.frequency_set_before_go: bool | None = None
        self._drive: tuple[float, list[int], list[str], float, dict[str, int]] | None = None
        self._halt_flag = threading.Event()
        self.master, self._slave = os.openpty()
        self.port = os.ttyname(self._slave)
        self._thread = threading.Thread(target=self._serve, daemon=True)

    @property
    def url(self) -> str:
        return f"mm3a://{self.port}"

    @property
    def driving(self) -> bool:
        return self._drive is not None

    def commands(self) -> list[str]:
        return [c for _, c in self.log]

    def __enter__(self) -> ConsolePeer:
        import tty

        tty.setraw(self._slave)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._halt_flag.set()
        self._thread.join(timeout=2)
        os.close(self.master)
        os.close(self._slave)

    # -- line ---------------------------------------------------------------------------
    def _say(self, status: str, text: str = "") -> None:
        if not self.mute:
            os.write(self.master, f"{status}\t{text}\r".encode("ascii"))

    def _serve(self) -> None:
        pending = b""
        while not self._halt_flag.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.01)
            if not ready:
                continue
            try:
                pending += os.read(self.master, 256)
            except OSError:
                return
            while b"\r" in pending:
                line, _, pending = pending.partition(b"\r")
                self._command(line, time.monotonic())

    # -- steps --------------------------------------------------------------------------
    def _halt_all(self, t: float) -> None:
        if self._drive is None:
            return
        t0, mults, values, interval, hz = self._drive
        elapsed = t - t0
        for i, ch in enumerate("ABCD"):
            m = mults[i]
            if m == 0:
                continue
            per = int(values[i][1:]) * abs(m)
            made = 0
            start = 0.0
            while start < elapsed:  # each interval that has begun
                made += min(per, math.ceil((elapsed - start) * hz[ch]))
                start += interval
            signed = made if m > 0 else -made
            if values[i][0] == "f":
                self.fine[ch] += signed
            else:
                self.steps[ch] += signed
        self._drive = None

    def _command(self, raw: bytes, t: float) -> None:
        text = raw.decode("ascii", "replace")
        self.log.append((t, text))
        if ";" in text or "\n" in text:
            self.violations.append(f"not a console command: {text!r}")
            self._say("e", "syntax")
            return
        words = text.split()
        if not words:
            self._say("e", "empty")
            return
        head, args = words[0], words[1:]
        if head == "stopnack":
            self._halt_all(t)
            return
        if head == "stop":
            self._halt_all(t)
            self._say("o")
            return
        if head == "version":
            self._say("o", "NanoControl peer console 9.9")
            return
        if head == "frequency" and len(args) == 4 and all(a.isdigit() and 300 <= int(a) <= 20000 for a in args):
            self.hz = {ch: int(a) for ch, a in zip("ABCD", args, strict=True)}
            if self.frequency_set_before_go is None:
                self.frequency_set_before_go = True
            self._say("o")
            return
        if head == "speed":
            if args == ["?"]:
                padded = [f"{v[0]}{int(v[1:]):03d}" for v in self.profiles[self.active]]
                self._say("o", f"{self.active} " + " ".join(padded))
                return
            if args and args[0] in "123456" and len(args[0]) == 1:
                p = int(args[0])
                if len(args) == 1:
                    self.active = p
                    self._say("o")
                    return
                ok = len(args) == 5 and all(
                    len(v) == 3 and v[0] in "cf" and v[1:].isdigit() and 1 <= int(v[1:]) <= 64 for v in args[1:]
                )
                if ok:
                    self.profiles[p] = args[1:]
                    self._say("o")
                    return
            self._say("e", "speed syntax")
            return
        if head == "go":
            if self.frequency_set_before_go is None:
                self.frequency_set_before_go = False
            try:
                mults = [int(a) for a in args[:4]]
                interval = int(args[4]) / 1000.0
            except (ValueError, IndexError):
                self._say("e", "go syntax")
                return
            if len(args) != 5 or any(abs(m) > 100 for m in mults) or interval <= 0:
                self._say("e", "go range")
                return
            if self.fault == "error":
                self._say("e", "motor driver fault")
                return
            self._halt_all(t)
            self._drive = (t, mults, list(self.profiles[self.active]), interval, dict(self.hz))
            if self.fault == "silent":
                self.mute = True
            self._say("o")
            return
        if head in ("beep", "finewithcoarse"):
            self._say("o")
            return
        self._say("e", f"unknown {head}")
