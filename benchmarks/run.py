"""Run every benchmark in this folder (``make bench``): each prints its own table of ratios."""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    names = sys.argv[1:] or sorted(p.stem for p in HERE.glob("bench_*.py"))
    for name in names:
        path = HERE / f"{name}.py"
        print(f"\n=== {name} " + "=" * max(0, 70 - len(name)))
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod  # dataclasses look their module up while the module runs
        assert spec.loader is not None
        t = time.perf_counter()
        spec.loader.exec_module(mod)
        mod.main()
        print(f"({name}: {time.perf_counter() - t:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
