"""The scaling benchmark runs end to end at tiny sizes (what CI runs; timings are printed, never asserted).

``make bench`` runs it at full size (1e3 .. 1e6 rows); see README "Performance".
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_scale.py"


def test_scaling_benchmark_runs_quick(capsys):
    spec = importlib.util.spec_from_file_location("bench_scale", BENCH)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_scale"] = mod
    spec.loader.exec_module(mod)
    rows = mod.main(["--quick"])
    out = capsys.readouterr().out
    series = [r for r in rows if "rows" in r]
    assert {r["command"] for r in series} == {"predict", "calibrate", "fit", "anova", "import"}
    assert all(r["exit"] == 0 and r["seconds"] > 0 and r["peak_mib"] > 0 for r in series)
    grown = [r for r in rows if "exponent" in r]
    assert [r["command"] for r in grown] == ["calibrate"] and all(math.isfinite(r["exponent"]) for r in grown)
    for what in ("growth exponent", "pandas read_csv", "statsmodels", "per-move quadrature", "start-up"):
        assert what in out


def test_the_ablation_renderer_takes_every_argument_the_scene_renders_with():
    """``vision_ablation``'s patched scene (used by ``vision_ground`` too) renders what the own renderer asks:
    an argument ``SimScene.render`` gained (the droplets) must reach it, or the script fails with a TypeError."""
    import inspect

    from stickslip.sim.camera import SimScene

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "vision_ablation.py"
    spec = importlib.util.spec_from_file_location("vision_ablation", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ours = list(inspect.signature(mod.ablated(frozenset({"drift"})).render).parameters)
    assert ours == list(inspect.signature(SimScene.render).parameters)


def test_the_textured_substrate_keeps_the_random_draws(monkeypatch):
    """``vision_hidden --texture``: the substrate's texture contrast scaled, every other draw the same (scale 1:
    the simulator's substrate itself; scale 3: it plus twice the texture term, and the stream after it unmoved)."""
    import numpy as np

    import stickslip.sim.camera as sim_camera

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "vision_hidden.py"
    spec = importlib.util.spec_from_file_location("vision_hidden", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    plain = sim_camera._substrate
    monkeypatch.setattr(sim_camera, "_substrate", plain)  # put back after the test
    base_rng = np.random.default_rng(7)
    base = plain(40, 50, "optical", 3, base_rng)
    after = base_rng.random()
    for scale in (1.0, 3.0):
        mod._textured(scale)
        rng = np.random.default_rng(7)
        got = sim_camera._substrate(40, 50, "optical", 3, rng)
        assert rng.random() == after
        sim_camera._substrate = plain
        if scale == 1.0:
            np.testing.assert_allclose(got, base, atol=1e-12)
        else:
            extra = (got - base) / (2.0 * 0.04)  # twice the texture term: unit spread
            assert abs(float(np.std(extra)) - 1.0) < 1e-9 and np.ptp(extra) > 1.0
