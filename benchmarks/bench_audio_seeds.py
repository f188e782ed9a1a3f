"""The audio battery on other draws: every condition with its training and test recordings' seeds moved.

``tests/test_audio_battery.py`` holds ~65 named conditions, each one draw of the battery's
generator (``tests/support/battery_sound.py``): the detector was developed on those draws. Here
each condition is run again with every seed moved by ``1000 x k`` (k = 1 .. ``--seeds``), so
the same conditions are heard on draws nobody tuned to; the table prints, per draw, the groups'
pass counts and every condition that failed (and how: missed, late, a false alarm, refused).

Run: ``.venv/bin/python benchmarks/bench_audio_seeds.py --seeds 5`` (a minute or two per draw on
2 cores; the espeak-ng conditions are skipped where it is not installed).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))  # the battery (test_audio_battery.py)
sys.path.insert(0, str(HERE.parent / "tests" / "support"))  # its generator

from battery_sound import espeak_speech  # noqa: E402

import test_audio_battery as tb  # noqa: E402


def _moved(c: tb.Condition, k: int) -> tb.Condition:
    return replace(
        c, train=replace(c.train, seed=c.train.seed + 1000 * k), test=replace(c.test, seed=c.test.seed + 1000 * k)
    )


def _how(c: tb.Condition, o: tb.Outcome) -> str:
    if c.expect == "refused":
        return "not refused"
    if o.refused:
        return "refused: " + o.refused[:50]
    if not o.hits:
        return "missed" + (f" ({len(o.events)} events elsewhere)" if o.events else "")
    lat = o.latency_s
    if o.false_alarms:
        return f"{o.false_alarms} false alarm(s)"
    if lat is not None and lat > 0.050 + c.late_s:
        return f"late ({1e3 * lat:.0f} ms{', found late' if o.late[o.hits[0]] else ''})"
    return "label warning differs"


def main(seeds: int = 3) -> None:
    espeak = espeak_speech(48_000) is not None
    conds = [c for c in tb.CONDITIONS if espeak or not tb._needs_espeak(c)]
    print(
        f"the battery on {seeds} other draws ({len(conds)} conditions; espeak-ng {'on' if espeak else 'not installed'})"
    )
    for k in range(0, seeds + 1):
        t = time.perf_counter()
        outs = {c.name: (c, tb.run(_moved(c, k))) for c in conds}
        groups = []
        for g in ("core", "cross", "hostile"):
            cs = [(c, o) for c, o in outs.values() if c.group == g]
            groups.append(f"{g} {sum(tb.passed(c, o) for c, o in cs)}/{len(cs)}")
        lat = sorted(o.fast_latency_s for c, o in outs.values() if o.fast_latency_s is not None and c.late_s == 0)
        med = 1e3 * lat[len(lat) // 2] if lat else float("nan")
        p95 = 1e3 * lat[min(len(lat) - 1, int(0.95 * len(lat)))] if lat else float("nan")
        label = "the battery's own draw" if k == 0 else f"seeds + {1000 * k}"
        print(
            f"{label}: {', '.join(groups)}; latency median {med:.1f} ms, p95 {p95:.1f} ms "
            f"({time.perf_counter() - t:.0f} s)"
        )
        for c, o in outs.values():
            if not tb.passed(c, o):
                tag = " (known failure)" if c.known_failure else ""
                print(f"    {c.name}: {_how(c, o)}{tag}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="The audio battery on other draws (module docstring).")
    ap.add_argument("--seeds", type=int, default=3, help="how many other draws (each seed + 1000 k)")
    main(ap.parse_args().seeds)
