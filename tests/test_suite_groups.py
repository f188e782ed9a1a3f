"""The suite's own scheduling: an ``xdist_group`` keeps its tests on one worker.

Modules that share an expensive fixture (the documentation site's build, the LuGre arm's
acceptance runs, the fuzzed control room) are marked with one group each, so that ``make test``
(``--dist loadgroup``) builds the fixture once. pytest 9.2 silently broke that (the group suffix
no longer reaches the test's id, pytest-xdist issue 1386), which doubled those builds without
failing anything; pyproject.toml keeps pytest below 9.2 and this test fails if it happens again.
"""

from __future__ import annotations

import os

import pytest

pytestmark = pytest.mark.xdist_group("suite_groups")


def test_a_grouped_test_carries_its_group_under_loadgroup(request: pytest.FixtureRequest) -> None:
    if not os.environ.get("PYTEST_XDIST_WORKER") or not getattr(request.config.option, "loadgroup", False):
        pytest.skip("only meaningful on an xdist worker under --dist loadgroup (as make test runs)")
    assert request.node.nodeid.endswith("@suite_groups"), request.node.nodeid
