"""The spread design (``calibration.design.spread_poses``): maximum projection and maximin, greedy."""

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
    chosen = spread_poses(joint, 5, seed=4, existing=paper_poses(joint), candidates=60, criterion="maxpro")
    sites = load_coordinates(joint, paper_poses(joint))
    for i, pose in enumerate(chosen):
        terms = _criterion_terms(joint, x, sites)
        terms[[cand.index(p) for p in chosen[:i]]] = np.inf
        k = cand.index(pose)
        assert k == int(np.argmin(terms))
        sites = np.vstack([sites, x[k]])


@pytest.mark.parametrize("joint", [3, 2])
def test_each_maximin_pose_is_the_candidate_farthest_from_the_rest(joint):
    cand = workspace_poses(joint, 60, seed=6)
    x = load_coordinates(joint, cand)
    chosen = spread_poses(joint, 5, seed=6, existing=paper_poses(joint), candidates=60, criterion="maximin")
    sites = load_coordinates(joint, paper_poses(joint))
    for pose in chosen:
        k = cand.index(pose)
        d = np.min(np.linalg.norm(x[:, None, :] - sites[None, :, :], axis=-1), axis=1)
        assert d[k] == pytest.approx(np.max(d), rel=1e-12)
        sites = np.vstack([sites, x[k]])


@pytest.mark.parametrize("seed", range(6))
def test_max_projection_fills_each_load_s_range_not_only_its_ends(seed):
    # with the paper's poses (|cos q2| = 0 or 1; q3 at 0 or 12 mm) the design fills the middle of each
    # coordinate's range: measured over seeds 0-39, the widest gap 0.29 of [0, 1] in |cos q2| (median
    # 0.22) and 0.52 of [-1, 1] in q3 (median 0.39); the greedy maximin design leaves 0.70 and 0.92
    # (medians) empty, its poses at the ends
    for joint, col, lo, hi, widest in ((3, 3, 0.0, 1.0, 1 / 3), (2, 15, -1.0, 1.0, 0.6)):
        poses = spread_poses(joint, 8, seed, existing=paper_poses(joint), criterion="maxpro")
        x = load_coordinates(joint, poses + paper_poses(joint))[:, col]
        assert np.max(np.diff(np.sort(np.r_[lo, x, hi]))) <= widest, (joint, np.sort(x))
    maximin = spread_poses(3, 8, seed, existing=paper_poses(3), criterion="maximin")
    x = load_coordinates(3, maximin + paper_poses(3))[:, 3]
    assert np.max(np.diff(np.sort(np.r_[0.0, x, 1.0]))) > 0.4, np.sort(x)  # 0.46 at least over seeds 0-39


def test_defaults_reproducibility_and_bad_criterion():
    # joint 3 spreads each load's projection, the rotary joints keep the maximin design (docs/models.md §3)
    assert spread_poses(3, 4, 2, paper_poses(3)) == spread_poses(3, 4, 2, paper_poses(3), criterion="maxpro")
    assert spread_poses(2, 4, 2, paper_poses(2)) == spread_poses(2, 4, 2, paper_poses(2), criterion="maximin")
    a = spread_poses(3, 4, seed=9)
    assert a == spread_poses(3, 4, seed=9) and len(set(a)) == 4
    x = load_coordinates(3, workspace_poses(3, 2000, seed=9))
    assert load_coordinates(3, a[:1])[0] == pytest.approx(x[np.argmax(np.linalg.norm(x - x.mean(axis=0), axis=1))])
    assert spread_poses(2, 0) == []
    with pytest.raises(ValueError, match="criterion 'lhs'"):
        spread_poses(3, 2, criterion="lhs")
