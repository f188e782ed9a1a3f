"""An independent NanoControl (legacy command set) on a pseudo-terminal, for the tests.

Written from the command-set description only, sharing no code with
``stickslip.sim.emulators``: commands end in ``;``, answers are ``o<TAB>text`` /
``e<TAB>text`` ended by CR LF (the project's emulator uses a bare CR), a ``coarse``
burst is answered once its steps are done at the channel's stepping frequency, and the
peer keeps a log of every command and the steps each channel made. It moves no arm:
tests compare the steps it received with what ``stickslip plan`` says.

Faults (``fault=``): ``"error"`` answers ``coarse`` with ``e``; ``"silent"`` never answers
``coarse``; ``"garbage"`` answers ``coarse`` with binary noise.
"""

from __future__ import annotations

import os
import select
import threading
import time


class NanoControlPeer:
    def __init__(self, fault: str | None = None, hz: float = 5000.0):
        self.fault = fault
        self.hz = hz
        self.log: list[str] = []
        self.steps = {c: 0 for c in "ABCD"}
        self._stop = threading.Event()
        self.master, slave = os.openpty()
        self.port = os.ttyname(slave)
        self._slave = slave
        self._thread = threading.Thread(target=self._serve, daemon=True)

    @property
    def url(self) -> str:
        return f"mm3a://{self.port}?timeout=0.5"

    def __enter__(self) -> NanoControlPeer:
        import tty

        tty.setraw(self._slave)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        os.close(self.master)
        os.close(self._slave)

    def _reply(self, text: str) -> None:
        os.write(self.master, text.encode() + b"\r\n")

    def _serve(self) -> None:
        buf = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.02)
            if not ready:
                continue
            try:
                buf += os.read(self.master, 1024)
            except OSError:
                return
            while b";" in buf:
                raw, buf = buf.split(b";", 1)
                self._handle(raw.decode("ascii", "replace").strip())

    def _handle(self, cmd: str) -> None:
        self.log.append(cmd)
        words = cmd.split()
        if not words:
            return
        name = words[0].lower()
        if name == "stop":
            self._reply("o\tstopped")
        elif name == "version":
            self._reply("o\tNanoControl peer 2.4")
        elif name == "coarse" and len(words) == 3:
            if self.fault == "silent":
                return
            if self.fault == "garbage":
                os.write(self.master, b"\x00\xff\xfe\x07garbage\r\n")
                return
            if self.fault == "error":
                self._reply("e\tamplifier overheated")
                return
            ch, n = words[1].upper(), int(words[2])
            time.sleep(abs(n) / self.hz)
            self.steps[ch] += n
            self._reply("o\tdone")
        elif name in ("speed", "amplitude", "pause", "counterreset"):
            self._reply("o\tok")
        else:
            self._reply(f"e\tunknown command {name}")
