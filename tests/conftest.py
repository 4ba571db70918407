"""Suite-wide hypothesis profile (see tests/helpers.py): deadline off, blobs printed,
example counts scaled by the LIGHTSCHED_EXAMPLES environment variable. The ``tuning``
fixture (and ``grid_kind``, its name): the oracle modules' tests run once per kind of
object grid, each passing that Tuning to the fast schedulers it makes. And a guard
against stale numba caches (below)."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import pytest


def _drop_stale_numba_cache() -> None:
    """numba keys a cached kernel on its own source file only, so a kernel of objects.py that
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

from lightsched.tuning import Tuning  # noqa: E402

register_profile()

# The Tuning that forces each kind of grid of the fast path (grid.py): every object in it
# (an invisible object's record masked: simd.SHOWN), or only the visible objects (and a
# second grid of the invisible casters near shadowed point and spot lights); and with each,
# one of the two ways of each choice below (and of copying the output rows an incremental
# frame keeps: on every thread or on the calling one).
TUNINGS = {
    "every": Tuning(every_object_share=0.0, candidate_min_objects=0,
                    direct_tests_per_light=1e18, grid_tests_per_object=1e18,
                    near_scan_pairs=0, few_pairs=math.inf, parallel_copy_bytes=0),
    "visible": Tuning(every_object_share=math.inf, candidate_min_objects=0,
                      direct_tests_per_light=-1e18, grid_tests_per_object=-1e18,
                      near_scan_pairs=0, few_pairs=-1, parallel_copy_bytes=1 << 62),
}


@pytest.fixture(params=sorted(TUNINGS), scope="module")
def grid_kind(request: pytest.FixtureRequest) -> str:
    """The name of the kind of grid ``tuning`` forces ("every" or "visible"), for tests
    whose expectations depend on it."""
    return request.param


@pytest.fixture(scope="module")
def tuning(grid_kind: str) -> Tuning:
    """The Tuning a test passes to every fast scheduler it makes, once per kind of grid
    (a module's tests run with each): most test scenes stand in front of the camera, so
    the scheduler's own choice (every object once half are visible) would leave the grid
    of visible objects untested. Full frames of these modules' small scenes take the
    candidate lists' path where it applies (large scenes only, otherwise:
    candidate_min_objects). Objects that move or come into view in an incremental frame
    get their pairs from a test against every light with the first kind, from a grid of
    the lights with the second; and the pairs of the lights an incremental frame walks
    again are grouped by sorting with the first, by a histogram of every object with the
    second (the scheduler chooses both by counts, direct_tests_per_light,
    grid_tests_per_object and few_pairs, which small scenes would not cross). With both,
    an incremental frame whose flagged lights did not change finds the objects holding
    their pairs by walking them (near_scan_pairs: the scheduler walks them only where the
    cache holds thousands of pairs per flagged light); where they changed, it scans every
    object's pairs."""
    return TUNINGS[grid_kind]
