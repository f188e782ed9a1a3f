"""``tune`` remembered for one test session: a recording tuned with the same arguments is tuned once.

Many audio tests tune the same generated recording (an arm's tuning scene, a battery's
training sound, the hour generator's joint), and a tuning costs seconds: its self-check runs
the detector on the recording again and again with interference injected. :func:`tune` is
:func:`stickslip.audio.tuning.tune`, deterministic for given samples and arguments (the
self-check's interference is seeded), so its answer can be kept.

The key is a SHA-256 of the samples' bytes, dtype and shape, the sample rate, the label and
every keyword. The answers are kept in this process and, where ``$STICKSLIP_TEST_TUNINGS``
names a folder (``tests/conftest.py`` makes one per session, shared by the xdist workers and
removed at the end), in files there, so no answer outlives the code that made it. Each
caller gets its own copy. A refusal (:class:`~stickslip.audio.tuning.TuningError`) is not
kept: it is tuned again. Tests of ``tune`` itself call it directly.
"""

from __future__ import annotations

import copy
import hashlib
import os
import pickle
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # imported when first tuning: tests/conftest.py reads ENV from here and stays light
    from stickslip.audio.tuningfile import Tuning

__all__ = ["ENV", "tune"]

ENV = "STICKSLIP_TEST_TUNINGS"
"""The environment variable naming the session's folder of kept tunings."""

_KEPT: dict[str, Tuning] = {}


def _key(samples: Any, sample_rate: Any, stop_at_s: Any, joint: Any, kw: dict[str, Any]) -> str:
    a = np.ascontiguousarray(np.asarray(samples))
    h = hashlib.sha256(repr((a.dtype.str, a.shape, sample_rate, stop_at_s, joint, sorted(kw.items()))).encode())
    h.update(a.tobytes())
    return h.hexdigest()


def _load(path: Path) -> Tuning | None:
    from stickslip.audio.tuningfile import Tuning

    try:
        tu = pickle.loads(path.read_bytes())
    except (OSError, EOFError, pickle.UnpicklingError):
        return None  # not there yet, or another worker's file half written: tune it here
    return tu if isinstance(tu, Tuning) else None


def _keep(path: Path, tu: Tuning) -> None:
    """Write the answer whole or not at all (a worker reading it meanwhile sees no file or all of it)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".part")
    with os.fdopen(fd, "wb") as f:
        pickle.dump(tu, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)


def tune(samples: Any, sample_rate: Any, stop_at_s: Any, joint: Any = None, **kw: Any) -> Tuning:
    """:func:`stickslip.audio.tuning.tune` (the same arguments), answered from the session's kept tunings."""
    key = _key(samples, sample_rate, stop_at_s, joint, kw)
    tu = _KEPT.get(key)
    folder = os.environ.get(ENV)
    path = Path(folder) / f"{key}.pickle" if folder else None
    if tu is None and path is not None:
        tu = _load(path)
    if tu is None:
        from stickslip.audio.tuning import tune as _tune

        tu = _tune(samples, sample_rate, stop_at_s, joint, **kw)
        if path is not None and path.parent.is_dir():
            _keep(path, tu)
    _KEPT[key] = tu
    return copy.deepcopy(tu)
