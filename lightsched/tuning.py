"""Tuning: the thresholds and margins by which a frame's plan chooses its paths (DESIGN
section 6). None of them changes a result, only how it is found; the tests pass their own
Tuning to force each path on small scenes. Where each value comes from (the measurements)
is in bench/RESULTS.md, "Tuning (lightsched/tuning.py)".

Constants that numba compiles into the kernels (work-item sizes, the grid's z split, the K
values with a static trip count) stay module constants of their kernels' modules: a kernel
cannot read a dataclass without being compiled again for each value.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tuning:
    """The scheduler's thresholds and margins (``Scheduler(config, tuning)``)."""

    # Below this many (competing point or spot light, object) pairs the grid of objects
    # is a single cell: brute force costs less than the cells.
    brute_force_pairs: int = 1 << 15
    # Grid cell edge over the median radius of the competing point and spot lights.
    cell_per_radius: float = 1.5
    # With at least this share of the objects visible, the grid holds every object (a
    # camera move then only changes its records' masks); below it, the visible ones only.
    every_object_share: float = 0.5
    # A kept grid of every object serves while its cell edge is within this factor of the
    # one the lights ask for ...
    cell_slack: float = 1.25
    # ... checked again once this share of the competing lights changed, or a radius did.
    edge_drift: float = 0.01
    # An incremental frame beyond this share of changed lights or objects runs in full.
    full_share: float = 0.5
    # "fast" precision keeps its float32 records relative to the first camera's position
    # until that camera is this far from it (metres): within 2^8 m, the 2^-16 m grid is
    # exact in float32.
    reanchor: float = 256.0
    # Objects that moved or came into view are tested against every competing point or
    # spot light while the tests number at most this many per light plus one per object
    # row; beyond, against the lights of the cells their box overlaps in a grid of lights.
    direct_tests_per_light: float = 24.0
    # With that grid of lights already made, direct tests serve only below this many
    # lights per object.
    grid_tests_per_object: float = 110.0
    # The objects holding the pairs of flagged lights are found by walking those lights
    # while the cache holds at least this many pairs per flagged light; below, by a scan
    # of every object's pairs.
    near_scan_pairs: float = 4096.0
    # The walked lights' pairs are grouped by sorting while they number at most this many
    # per object; beyond, with a histogram of every object.
    few_pairs: float = 1 / 32
    # Candidate lists (Verlet lists) at all (False: full frames walk every light).
    candidate_lists: bool = True
    # Grids of fewer objects walk every light: the lists' upkeep costs more there.
    candidate_min_objects: int = 1 << 12
    # A candidate list holds the objects within its light's radius times 1 + skin ...
    skin: float = 0.1
    # ... centred this share of skin x radius ahead along the light's last step (< 1).
    lead: float = 0.8
    # The lists are made again from scratch when more than this share of the lights left
    # their widened spheres.
    rebuild_share: float = 0.5
    # An incremental frame copies the rows of last frame's outputs it does not write on
    # the calling thread up to this many bytes, on every thread beyond: waking the other
    # thread costs several microseconds, a few hundred rows' copy.
    parallel_copy_bytes: int = 1 << 16
