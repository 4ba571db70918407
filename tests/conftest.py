"""Suite-wide hypothesis profile (see tests/helpers.py): deadline off, blobs printed,
example counts scaled by the LIGHTSCHED_EXAMPLES environment variable. The ``grid_kind``
fixture: the oracle modules run once per kind of object grid. And a guard against stale
numba caches (below)."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterator
from pathlib import Path

import pytest


def _drop_stale_numba_cache() -> None:
    """numba keys a cached kernel on its own source file only, so a kernel of pairs.py that
    inlines fade.py, select.py or simd.py keeps running the old helpers after they are
    edited (a mutation of fade.py passed the oracle tests that way). The cache is dropped
    whenever any source of the package changed since it was written; the digest sits
    beside it. Runs before a kernel is called; xdist's workers find the digest current."""
    package = Path(__file__).resolve().parent.parent / "lightsched"
    cache = package / "__pycache__"
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in sorted(package.glob("*.py"))))
    stamp = cache / "numba-sources.sha256"
    if stamp.exists() and stamp.read_text() == digest.hexdigest():
        return
    for stale in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:
        stale.unlink(missing_ok=True)
    cache.mkdir(exist_ok=True)
    stamp.write_text(digest.hexdigest())


_drop_stale_numba_cache()

# After the guard, so that no kernel has been loaded from the cache yet.
from helpers import register_profile  # noqa: E402

from lightsched import scheduler  # noqa: E402

register_profile()

# EVERY_OBJECT_SHARE that forces each kind of grid of the fast path (scheduler.py): every
# object in it (an invisible object's record masked: simd.SHOWN), or only the visible objects
# (and a second grid of the invisible casters near shadowed point and spot lights).
GRID_KINDS = {"every": 0.0, "visible": math.inf}


@pytest.fixture(params=sorted(GRID_KINDS), scope="module")
def grid_kind(request: pytest.FixtureRequest) -> Iterator[str]:
    """Runs a module's tests with each kind of grid: most test scenes stand in front of the
    camera, so the scheduler's own choice (every object once half are visible) would leave
    the grid of visible objects untested. Full frames of these modules' small scenes take
    the candidate lists' path where it applies (large scenes only, otherwise). Objects
    that move or come into view in an incremental frame get their pairs from a test
    against every light with the first kind, from a grid of the lights with the second;
    and the pairs of the lights an incremental frame walks again are
    grouped by sorting with the first, by a histogram of every object with the second
    (the scheduler chooses both by counts, DIRECT_TESTS_PER_LIGHT, GRID_TESTS_PER_OBJECT
    and FEW_PAIRS, which small scenes would not cross). With both, an incremental frame
    whose flagged lights did not change finds the objects holding their pairs by walking
    them (NEAR_SCAN_PAIRS: the scheduler walks them only where the cache holds thousands
    of pairs per flagged light); where they changed, it scans every object's pairs."""
    names = ("EVERY_OBJECT_SHARE", "CANDIDATE_MIN_OBJECTS", "DIRECT_TESTS_PER_LIGHT",
             "GRID_TESTS_PER_OBJECT", "FEW_PAIRS", "NEAR_SCAN_PAIRS")
    old = {name: getattr(scheduler, name) for name in names}
    every = request.param == "every"
    scheduler.EVERY_OBJECT_SHARE = GRID_KINDS[request.param]
    scheduler.CANDIDATE_MIN_OBJECTS = 0
    scheduler.DIRECT_TESTS_PER_LIGHT = 1e18 if every else -1e18
    scheduler.GRID_TESTS_PER_OBJECT = 1e18 if every else -1e18
    scheduler.NEAR_SCAN_PAIRS = 0
    scheduler.FEW_PAIRS = math.inf if every else -1
    yield request.param
    for name, value in old.items():
        setattr(scheduler, name, value)
