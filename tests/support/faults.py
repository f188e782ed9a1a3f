"""An independent fault injector for the move journal and the device lock.

Not the project's emulators: a bare Controller written from the journal's point of view.
It counts what it was asked for, drops the link after ``drop_after`` bursts (raising
DeviceError mid-burst, after having moved part of the burst), or confirms every burst
late (``delay`` seconds), so concurrent processes overlap.

URLs (register with :func:`install`): ``faulty://name?drop_after=2&partial=0.5&delay=0``.
Moved steps are appended to the file named by ``log`` (one signed int per line) so a
test can compare what the "hardware" did with what the database says.
"""

from __future__ import annotations

import time
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from stickslip.devices.base import DeviceError, DeviceInfo, register_backend


class FaultyController:
    def __init__(self, url: str) -> None:
        q = {k: v[-1] for k, v in parse_qs(urlsplit(url).query).items()}
        self.drop_after = int(q.get("drop_after", -1))
        self.partial = float(q.get("partial", 0.5))
        self.delay = float(q.get("delay", 0.0))
        self.log = Path(q["log"]) if "log" in q else None
        self.url = url
        self.bursts = 0
        self.moved = 0

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(model="fault injector", url="faulty://", joints=(1, 2, 3))

    def _record(self, n: int) -> None:
        self.moved += n
        if self.log is not None:
            with open(self.log, "a") as f:
                f.write(f"{n}\n")

    def step(self, joint: int, n: int) -> None:
        if self.bursts == self.drop_after:
            part = int(n * self.partial)
            self._record(part)  # the arm moved part of the burst, then the link dropped
            raise DeviceError(f"faulty://: link dropped after {part} of {n} steps")
        time.sleep(self.delay)
        self._record(n)
        self.bursts += 1

    def set_frequency(self, joint: int, hz: float) -> None: ...
    def frequency(self, joint: int) -> float:
        return 1000.0

    def stop(self, joint: int | None = None) -> None: ...
    def settings(self) -> dict[str, object]:
        return {}

    def close(self) -> None: ...


def install() -> None:
    register_backend("faulty", FaultyController)
