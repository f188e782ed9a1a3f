"""A scripted session of the device commands (move, where, observe, reach, jog, listen), recorded.

Every step runs in-process through typer's ``CliRunner`` and is recorded as the command
line, its exit code, its stdout and stderr, and the rows it left in the database (the
``device_state`` table: positions, tracks, journal). The script runs on ``sim://``, on the
legacy NanoControl emulator and on the console emulator, so a change that moves code
around can be checked to leave every output and every stored row as it was
(``tests/test_cli_script.py`` compares a run with ``tests/data/cli_script.json``).

Machine-dependent text is normalised: the temporary folder becomes ``<TMP>``, an
emulator's pseudo-terminal ``<PTY>`` and a lock's holder is dropped (it names the process).

Regenerate the recording (only when a change of output is intended, and say why in the
commit): ``python tests/support/cli_script.py tests/data/cli_script.json``.
"""

from __future__ import annotations

import json
import math
import os
import re
import sqlite3
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from typer.testing import CliRunner

SIM = "sim://?seed=4&day=2026-11-22"
DAY = "2026-11-22"


def true_calibration(path: Path) -> None:
    """A calibration holding the true models of :data:`SIM` (the simulator's own), saved to ``path``."""
    from stickslip import kinematics as kin
    from stickslip.calibration import Calibration
    from stickslip.sim.arm import SimulatedMM3A

    sim = SimulatedMM3A(seed=4, day=DAY)
    models = sim.true_models()
    consts = {}
    for (j, d), m in models.items():
        spec = kin.JOINTS[j]
        a, b = (spec.lower, spec.upper) if d == "+" else (spec.upper, spec.lower)
        consts[(j, d)] = float(m.average_gamma(a, b, *kin.Pose()))
    cal = Calibration(
        models=models, stderr=dict.fromkeys(models), constant_steps=consts, day=DAY, method="paper",
        created="2026-11-22T08:00:00+00:00",
    )
    cal.save(path)


def recordings(folder: Path) -> None:
    """A tuning recording, a test recording with a stop at 1.3 s, and one without a stop (joint 3)."""
    from stickslip.audio.sources import write_wav
    from stickslip.sim.sound import render_traverse_recording

    x, sr = render_traverse_recording(3, 1000.0, 2.0, 3.0, seed=21)
    write_wav(folder / "tune.wav", x, sr)
    y, _ = render_traverse_recording(3, 1000.0, 1.3, 2.0, seed=22, gain_db=2.0)
    write_wav(folder / "test.wav", y, sr)
    z, _ = render_traverse_recording(3, 1000.0, 1e9, 2.0, seed=23)
    write_wav(folder / "no_stop.wav", z, sr)


class ScriptedKeys:
    """Stands in for ``jog``'s terminal keys: each read returns the next group of key names, then ``q``."""

    script: list[list[str]] = []

    def __init__(self) -> None:
        self._left = [list(k) for k in type(self).script]

    def read(self, timeout: float) -> list[str]:
        return self._left.pop(0) if self._left else ["q"]

    def close(self) -> None:
        pass


class _QuietScreen:
    def show(self, status: Any) -> None:
        pass

    def close(self) -> None:
        pass


def _rows(db: Path) -> list[list[Any]]:
    """The ``device_state`` rows (device URL, key, value), the lock's holder left out."""
    if not db.exists():
        return []
    con = sqlite3.connect(db)
    try:
        rows = con.execute(
            "SELECT d.url, s.key, s.value FROM device_state s JOIN devices d ON d.id = s.device_id "
            "ORDER BY d.url, s.key"
        ).fetchall()
    finally:
        con.close()
    out: list[list[Any]] = []
    for url, key, value in rows:
        if key == "lock":
            value = "null" if value == "null" else "<held>"
        out.append([url, key, _rounded(json.loads(value))])
    return out


def _rounded(obj: Any) -> Any:
    """Floats to 12 significant digits (the last bits of a float sum are not behaviour)."""
    if isinstance(obj, float):
        return float(f"{obj:.12g}") if math.isfinite(obj) else str(obj)
    if isinstance(obj, dict):
        return {k: _rounded(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_rounded(v) for v in obj]
    return obj


class Session:
    """Runs commands against one temporary folder and database, recording each."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.db = tmp / "s.db"
        self.records: list[dict[str, Any]] = []
        self.subs: dict[str, str] = {str(tmp): "<TMP>"}
        self.runner = CliRunner()

    def _norm(self, text: str) -> str:
        for old, new in sorted(self.subs.items(), key=lambda kv: -len(kv[0])):
            text = text.replace(old, new)
        return re.sub(r"/dev/pts/\d+", "<PTY>", text)

    def run(self, *args: str, db: bool = True) -> dict[str, Any]:
        argv = [*args, "--db", str(self.db)] if db else list(args)
        r = self.runner.invoke(_app(), argv)
        rec = {
            "args": [self._norm(a) for a in args],
            "exit": r.exit_code,
            "stdout": self._norm(r.stdout),
            "stderr": self._norm(r.stderr),
            "rows": json.loads(self._norm(json.dumps(_rows(self.db)))),
        }
        if r.exception is not None and not isinstance(r.exception, SystemExit):
            rec["exception"] = repr(r.exception)
        self.records.append(rec)
        return rec


def _app() -> Any:
    from stickslip.cli import app

    return app


@contextmanager
def _jog_keys(*groups: list[str]) -> Iterator[None]:
    """``jog`` reads :class:`ScriptedKeys` and draws nothing while the block runs."""
    from stickslip.cli import taskspace

    ScriptedKeys.script = [list(g) for g in groups]
    fakes: dict[str, object] = {"_Keys": ScriptedKeys, "_Screen": _QuietScreen}  # jog's terminal part
    saved = {name: getattr(taskspace, name) for name in fakes}
    for name, fake in fakes.items():
        setattr(taskspace, name, fake)
    try:
        yield
    finally:
        for name, old in saved.items():
            setattr(taskspace, name, old)


def sim_part(s: Session, cal: str) -> None:
    s.run("where", "-d", SIM, "--offline", "--json")
    s.run("where", "-d", SIM, "--offline")
    s.run("where", "-d", SIM, "--set", "3=min", "--set", "2=-90deg", "--set", "1=0deg")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "3", "--by", "30um")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "3", "--to", "1mm", "--json")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "2", "--by", "2deg")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "3", "--by", "-20um", "--burst", "300")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "3", "--by", "30mm")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "3")
    s.run("observe", "-d", SIM, "--joint", "3", "--at", "1.0003mm", "--sigma", "1um")
    s.run("observe", "-d", SIM, "--joint", "3", "--at", "1.0001mm", "--json")
    s.run("observe", "-d", SIM, "--joint", "3", "--at", "1.5mm")
    s.run("move", "-d", SIM, "-c", cal, "--joint", "3", "--by", "50um")
    s.run("where", "-d", SIM)
    s.run("where", "-d", SIM, "--offline", "--json")
    s.run("reach", "-d", SIM, "-c", cal, "--by", "20um,-10um,5um", "--dry-run", "--json")
    s.run("reach", "-d", SIM, "-c", cal, "--by", "20um,-10um,5um", "--dry-run")
    s.run("reach", "-d", SIM, "-c", cal, "--by", "20um,-10um,5um")
    s.run("reach", "-d", SIM, "-c", cal, "--to", "1m,0,0")
    with _jog_keys(["m"], ["5", "d"], ["up"], [], ["pgdn"], []):
        s.run("jog", "-d", SIM, "-c", cal)
    s.run("where", "-d", SIM, "--offline")
    s.run("observe", "-d", SIM, "--joint", "3", "--at", "min")
    s.run("where", "-d", SIM, "--offline", "--json")


def emulator_part(s: Session, cal: str) -> None:
    from stickslip.sim.arm import SimulatedMM3A
    from stickslip.sim.emulators import NanoControlEmulator

    with NanoControlEmulator(SimulatedMM3A(seed=4, day=DAY)) as emu:
        s.run("where", "-d", emu.url)
        url = emu.url + "?dialect=legacy"  # the same device (the key has no query), opened without detection
        s.run("where", "-d", url, "--set", "3=min", "--q1", "0deg", "--q2", "-90deg", "--theta", "0deg")
        s.run("move", "-d", url, "-c", cal, "--trust-calibration", "--joint", "3", "--by", "100um")
        s.run("move", "-d", url, "-c", cal, "--trust-calibration", "--joint", "3", "--by", "-40um", "--json")
        s.run("observe", "-d", url, "--joint", "3", "--at", "60um", "--sigma", "2um")
        s.run("reach", "-d", url, "-c", cal, "--trust-calibration", "--by", "0um,5um,0um")
        s.run("where", "-d", url, "--offline")
        emu.inject("error", after=1)  # the second burst of the next move is refused: the joint is uncertain
        s.run("move", "-d", url + "&timeout=0.3", "-c", cal, "--trust-calibration", "--joint", "3", "--by", "60um",
              "--burst", "30")  # fmt: skip
        s.run("where", "-d", url, "--offline")
        s.run("move", "-d", url, "-c", cal, "--trust-calibration", "--joint", "3", "--by", "10um")
        emu.inject(None)
        s.run("observe", "-d", url, "--joint", "3", "--at", "min")
        s.run("where", "-d", url, "--offline", "--json")


def console_part(s: Session, cal: str) -> None:
    from stickslip.sim.arm import SimulatedMM3A
    from stickslip.sim.console_emulator import ConsoleEmulator

    with ConsoleEmulator(SimulatedMM3A(seed=4, day=DAY)) as con:
        url = con.url + "?hz=20000"
        s.run("where", "-d", url)
        s.run("where", "-d", url, "--set", "3=min", "--set", "2=-90deg", "--set", "1=0deg")
        s.run("move", "-d", url, "-c", cal, "--trust-calibration", "--joint", "3", "--by", "50um")
        s.run("move", "-d", url, "-c", cal, "--trust-calibration", "--joint", "2", "--by", "-0.1deg")
        s.run("where", "-d", url, "--offline", "--json")


def listen_part(s: Session) -> None:
    d = s.tmp
    tuning = str(d / "tuning.json")
    s.run("listen", str(d / "test.wav"), "--tuning", tuning, db=False)
    s.run("listen", str(d / "test.wav"), "--tuning", tuning, "--json", db=False)
    s.run("listen", str(d / "no_stop.wav"), "--tuning", tuning, db=False)
    s.run("listen", str(d / "test.wav"), "--tuning", tuning, "--confirm-s", "0", db=False)
    s.run("listen", str(d / "missing.wav"), "--tuning", tuning, db=False)


def tune_for_listen(folder: Path) -> None:
    """The tuning ``listen`` uses (made once, outside the recorded steps)."""
    from typer.testing import CliRunner

    argv = ["tune", str(folder / "tune.wav"), "--stop-at", "2.0", "--joint", "3", "-o", str(folder / "tuning.json")]
    r = CliRunner().invoke(_app(), argv)
    if r.exit_code != 0:
        raise RuntimeError(r.output)


PARTS: dict[str, Callable[[Session, str], None]] = {
    "sim": sim_part,
    "emulator": emulator_part,
    "console": console_part,
    "listen": lambda s, cal: listen_part(s),
}


def record(tmp: Path, parts: tuple[str, ...] = tuple(PARTS)) -> dict[str, list[dict[str, Any]]]:
    """Run the script's ``parts`` in ``tmp`` (with ``$STICKSLIP_TODAY`` pinned by the caller); the records."""
    cal = tmp / "cal.json"
    true_calibration(cal)
    if "listen" in parts:
        recordings(tmp)
        tune_for_listen(tmp)
    out = {}
    for name in parts:
        s = Session(tmp / name)
        s.tmp.mkdir()
        if name == "listen":
            for f in ("test.wav", "no_stop.wav", "tuning.json"):
                (s.tmp / f).write_bytes((tmp / f).read_bytes())
        s.subs[str(tmp)] = "<TMP>"
        PARTS[name](s, str(cal))
        out[name] = s.records
    return out


def main(argv: list[str]) -> int:
    """``python tests/support/cli_script.py OUT.json``: record the script into ``OUT.json``."""
    if len(argv) != 2:
        print("usage: cli_script.py OUT.json", file=sys.stderr)
        return 2
    os.environ["STICKSLIP_TODAY"] = DAY
    with tempfile.TemporaryDirectory() as t:
        os.environ["STICKSLIP_CONFIG"] = str(Path(t) / "no-config.toml")
        os.environ["STICKSLIP_DB"] = str(Path(t) / "unused.db")
        os.environ["COLUMNS"] = "80"
        data = record(Path(t))
    Path(argv[1]).write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
