"""The session's kept tunings (tests/support/tuned.py): a kept answer is only ever given for the same call."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import tuned

from stickslip.audio.tuningfile import Tuning


def test_the_key_changes_with_every_part_of_the_call():
    x = np.linspace(-0.5, 0.5, 4801).astype(np.float32)
    base = tuned._key(x, 48_000, 2.0, None, {"seed": 0})
    assert base == tuned._key(x.copy(), 48_000, 2.0, None, {"seed": 0})
    y = x.copy()
    y[1234] = np.nextafter(y[1234], np.float32(1.0))  # one sample, one bit
    others = [
        tuned._key(y, 48_000, 2.0, None, {"seed": 0}),
        tuned._key(x.astype(np.float64), 48_000, 2.0, None, {"seed": 0}),
        tuned._key(x.reshape(-1, 1), 48_000, 2.0, None, {"seed": 0}),
        tuned._key(x, 44_100, 2.0, None, {"seed": 0}),
        tuned._key(x, 48_000, 2.001, None, {"seed": 0}),
        tuned._key(x, 48_000, 2.0, 3, {"seed": 0}),
        tuned._key(x, 48_000, 2.0, None, {"seed": 1}),
        tuned._key(x, 48_000, 2.0, None, {"seed": 0, "self_check": False}),
    ]
    assert base not in others and len(set(others)) == len(others)


def test_a_kept_tuning_reads_back_whole_and_a_broken_file_is_tuned_again(tmp_path: Path):
    tu = Tuning(band_hz=(300.0, 8000.0), threshold_db=6.0, joint=3, checks={"warnings": []})
    path = tmp_path / "k.pickle"
    tuned._keep(path, tu)
    assert tuned._load(path) == tu and [p.name for p in tmp_path.iterdir()] == ["k.pickle"]
    path.write_bytes(path.read_bytes()[:20])  # another worker's file cut short
    assert tuned._load(path) is None
    assert tuned._load(tmp_path / "none.pickle") is None
    assert replace(tu, joint=2) != tu
