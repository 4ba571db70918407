"""Suite-wide hypothesis profile (see tests/helpers.py): deadline off, blobs printed,
example counts scaled by the LIGHTSCHED_EXAMPLES environment variable. And the
``grid_kind`` fixture: the oracle modules run once per kind of object grid."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from helpers import register_profile

from lightsched import scheduler

register_profile()

# EVERY_OBJECT_SHARE that forces each kind of grid of the fast path (scheduler.py): every
# object in it (an invisible object's record masked to 0), or only the visible objects
# (and a second grid of the invisible casters near shadowed point and spot lights).
GRID_KINDS = {"every": 0.0, "visible": math.inf}


@pytest.fixture(params=sorted(GRID_KINDS), scope="module")
def grid_kind(request: pytest.FixtureRequest) -> Iterator[str]:
    """Runs a module's tests with each kind of grid: most test scenes stand in front of the
    camera, so the scheduler's own choice (every object once half are visible) would leave
    the grid of visible objects untested."""
    old = scheduler.EVERY_OBJECT_SHARE
    scheduler.EVERY_OBJECT_SHARE = GRID_KINDS[request.param]
    yield request.param
    scheduler.EVERY_OBJECT_SHARE = old
