"""The comparator itself (helpers.assert_frames_match): near-ties pass, nothing else does."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_frames_match

from lightsched.frame import empty_frame


def frame(rows, k=3):
    """rows: per object a list of (light id, P, weight, state)."""
    f = empty_frame(np.arange(len(rows), dtype=np.int32), k, 4)
    f.cascade_splits = np.zeros((1, 5))
    for o, row in enumerate(rows):
        f.visible[o] = True
        f.count[o] = len(row)
        f.candidates[o] = len(row) + 1
        for j, (lid, p, w, st) in enumerate(row):
            f.light_ids[o, j] = lid
            f.light_index[o, j] = lid
            f.priority[o, j] = p
            f.fade_weight[o, j] = w
            f.fade_state[o, j] = st
    return f


BASE = [[(4, 3.0, 1.0, 2), (2, 1.0, 1.0, 2), (9, 1.0, 0.5, 1)], [(1, 5.0, 1.0, 2)]]


def test_identical_frames_pass_with_no_ties():
    assert assert_frames_match(frame(BASE), frame(BASE)) == 0
    assert assert_frames_match(frame(BASE), frame(BASE), tie_rel=0.0) == 0


def test_reordered_equal_priorities_pass_as_a_near_tie():
    fast = [[(4, 3.0, 1.0, 2), (9, 1.0, 0.5, 1), (2, 1.0, 1.0, 2)], BASE[1]]
    assert assert_frames_match(frame(fast), frame(BASE)) == 1  # weights follow their ids
    bad = [[(4, 3.0, 1.0, 2), (9, 1.0, 1.0, 2), (2, 1.0, 0.5, 1)], BASE[1]]
    with pytest.raises(AssertionError, match="weights"):
        assert_frames_match(frame(bad), frame(BASE))
    fast = [[(4, 3.0, 1.0, 2), (9, 1.0, 1.0, 2), (2, 1.0, 1.0, 2)], BASE[1]]
    ref = [[(4, 3.0, 1.0, 2), (2, 1.0, 1.0, 2), (9, 1.0, 1.0, 2)], BASE[1]]
    assert assert_frames_match(frame(fast), frame(ref)) == 1
    with pytest.raises(AssertionError, match="exact mode"):
        assert_frames_match(frame(fast), frame(ref), tie_rel=0.0)


def test_swap_at_the_cut_needs_a_near_tie():
    ref = [[(4, 3.0, 1.0, 2), (2, 1.0, 1.0, 2)]]
    assert assert_frames_match(frame([[(4, 3.0, 1.0, 2), (7, 1.0, 1.0, 2)]]), frame(ref)) == 1
    for p in (1.001, 1.0 + 1e-6):
        with pytest.raises(AssertionError, match="not a near-tie"):
            assert_frames_match(frame([[(4, 3.0, 1.0, 2), (7, p, 1.0, 2)]]), frame(ref))


def test_reorder_without_a_tie_fails():
    fast = [[(2, 1.0, 1.0, 2), (4, 3.0, 1.0, 2), (9, 1.0, 0.5, 1)], BASE[1]]
    with pytest.raises(AssertionError, match="not a near-tie"):
        assert_frames_match(frame(fast), frame(BASE))


def test_fading_out_order_is_strict():
    ref = [[(4, 3.0, 1.0, 2), (2, 1.0, 0.5, 3), (9, 1.0, 0.5, 3)]]
    fast = [[(4, 3.0, 1.0, 2), (9, 1.0, 0.5, 3), (2, 1.0, 0.5, 3)]]
    with pytest.raises(AssertionError, match="fading-out"):
        assert_frames_match(frame(fast), frame(ref))


@pytest.mark.parametrize("field,delta,ok", [("priority", 1e-7, True), ("priority", 1e-5, False),
                                            ("fade_weight", 5e-7, True), ("fade_weight", 1e-5, False)])
def test_float_tolerances(field, delta, ok):
    a, b = frame(BASE), frame(BASE)
    getattr(a, field)[0, 2] = np.float32(float(getattr(a, field)[0, 2]) * (1 + delta))
    if ok:
        assert assert_frames_match(a, b) == 0
        with pytest.raises(AssertionError):
            assert_frames_match(a, b, tie_rel=0.0)  # exact mode is bitwise
    else:
        with pytest.raises(AssertionError, match=field):
            assert_frames_match(a, b)


@pytest.mark.parametrize("field", ["count", "candidates", "visible", "light_index", "fade_state"])
def test_integer_fields_are_exact(field):
    a, b = frame(BASE), frame(BASE)
    arr = getattr(a, field)
    arr.reshape(-1)[0] = arr.reshape(-1)[0] ^ 1 if arr.dtype != bool else not arr.reshape(-1)[0]
    with pytest.raises(AssertionError):
        assert_frames_match(a, b)
