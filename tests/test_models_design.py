"""The spread design (``calibration.design.spread_poses``): a greedy maximum projection design."""

from __future__ import annotations

import numpy as np
import pytest
from physics_scenarios import paper_poses

from stickslip.calibration.design import load_coordinates, spread_poses, workspace_poses
from stickslip.calibration.groups import load_quantities


def _criterion_terms(joint: int, x: np.ndarray, sites: np.ndarray) -> np.ndarray:
    """``sum_j prod_q 1 / d_q^2`` of each row of ``x`` to ``sites``, written out without logs."""
    out = np.zeros(len(x))
    for s in sites:
        prod = np.ones(len(x))
        for q in load_quantities(joint):
            prod *= np.sum((x[:, q] - s[q]) ** 2, axis=1)
        with np.errstate(divide="ignore"):  # a candidate already chosen: an infinite term
            out += 1.0 / prod
    return out


@pytest.mark.parametrize("joint", [3, 2])
def test_each_pose_is_the_candidate_that_adds_least_to_the_max_pro_criterion(joint):
    # the design's definition, checked pose by pose against the criterion computed directly
    cand = workspace_poses(joint, 60, seed=4)
    x = load_coordinates(joint, cand)
    chosen = spread_poses(joint, 5, seed=4, existing=paper_poses(joint), candidates=60)
    sites = load_coordinates(joint, paper_poses(joint))
    for pose in chosen:
        k = cand.index(pose)
        terms = _criterion_terms(joint, x, sites)
        terms[[cand.index(p) for p in chosen[: chosen.index(pose)]]] = np.inf
        assert k == int(np.argmin(terms))
        sites = np.vstack([sites, x[k]])


@pytest.mark.parametrize("seed", range(6))
def test_every_load_quantity_s_range_is_filled_not_only_its_ends(seed):
    # with the paper's poses (|cos q2| = 0 or 1; q3 at 0 or 12 mm) the design fills the middle of each
    # coordinate's range: measured over seeds 0-39, the widest gap 0.29 of [0, 1] in |cos q2| (median
    # 0.22) and 0.52 of [-1, 1] in q3 (median 0.39); the greedy maximin design it replaced left 0.70
    # and 0.92 (medians) empty, its poses at the ends
    for joint, col, lo, hi, widest in ((3, 3, 0.0, 1.0, 1 / 3), (2, 15, -1.0, 1.0, 0.6)):
        poses = spread_poses(joint, 8, seed, existing=paper_poses(joint))
        x = load_coordinates(joint, poses + paper_poses(joint))[:, col]
        assert np.max(np.diff(np.sort(np.r_[lo, x, hi]))) <= widest, (joint, np.sort(x))


def test_reproducible_and_without_existing_poses():
    a = spread_poses(3, 4, seed=9)
    assert a == spread_poses(3, 4, seed=9) and len(set(a)) == 4
    x = load_coordinates(3, workspace_poses(3, 2000, seed=9))
    assert load_coordinates(3, a[:1])[0] == pytest.approx(x[np.argmax(np.linalg.norm(x - x.mean(axis=0), axis=1))])
    assert spread_poses(2, 0) == []
