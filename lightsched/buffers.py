"""Memory the stages reuse from frame to frame, so that a steady scene allocates no pair,
record or output memory per frame. Nothing here is a result: a stage that takes a buffer
writes it before it reads it. Large arrays matter most: at (1M, 100k) the pair heap's P
array (~36 MB) and the object records (~50 MB) are over glibc's mmap threshold, so a new
one each frame was mapped and faulted in again (bench/RESULTS.md, "Buffers").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .group import PairHeap
from .priority import aligned_empty


@dataclass
class SpareOutputs:
    """The per-object output arrays of the frame before the last (objects.py takes them
    back once nothing outside holds them), the rows by which they lag the last frame's
    (None: all of them) and that frame's visibility."""

    arrays: dict[str, np.ndarray]
    lag: np.ndarray | None
    visible: np.ndarray


class Buffers:
    """Named scratch arrays, the rows 0..n-1, the pair heap the last frame replaced, the
    outputs of the frame before the last, and two small caches of derived rows (see
    objects.run_rows and candidates.update_candidates)."""

    def __init__(self) -> None:
        self._named: dict[str, np.ndarray] = {}
        self.spare_heap: PairHeap | None = None
        self.spare_outputs: SpareOutputs | None = None
        self.kept_run: tuple[tuple[np.ndarray, ...], np.ndarray] | None = None
        self.hidden: tuple[np.ndarray, ...] | None = None
        # Which of two buffers in turn the objects stage keeps the replaced selection in.
        self.turn = 0

    def scratch(self, name: str, size: int, dtype: Any) -> np.ndarray:
        """A reusable 1-d buffer of at least ``size`` elements (grown by half when short)."""
        buf = self._named.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = aligned_empty(max(size, int(1.5 * (0 if buf is None else buf.size))), dtype)
            self._named[name] = buf
        return buf

    def zeros(self, name: str, shape: tuple[int, ...], dtype: Any) -> np.ndarray:
        """A read-only array of zeros, kept while its shape and dtype are: an output that
        is all zeros in a frame (the residual with Config.residual off) costs no write."""
        buf = self._named.get(name)
        if buf is None or buf.shape != shape or buf.dtype != dtype or buf.flags.writeable:
            buf = np.zeros(shape, dtype)
            buf.setflags(write=False)
            self._named[name] = buf
        return buf

    def rows(self, n: int, read_only: bool = True) -> np.ndarray:
        """0..n-1 (int64), kept while n is; a read-only view unless asked otherwise (the
        object pass's rows have the type of an incremental frame's: one signature)."""
        rows = self._named.get("rows")
        if rows is None or rows.size != n:
            rows = aligned_empty(n, np.int64)
            rows[:] = np.arange(n)
            self._named["rows"] = rows
        return read_only_view(rows) if read_only else rows

    def new_heap(self, room: int) -> PairHeap:
        """A pair heap of at least ``room`` records: the one
        the last frame replaced when it is large enough and not over twice that, else new
        arrays with an eighth more room, so that a scene a little larger next frame takes
        this one back."""
        spare, self.spare_heap = self.spare_heap, None
        if spare is not None and room <= spare.p.size <= 2 * room + 4096:
            return spare
        return PairHeap.empty(room + room // 8)


def read_only_view(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``. numba types an array's writability: the object pass's
    slot state and visibility are last frame's frozen outputs after the first frames and
    fresh arrays before, so passing them read-only always gives a kernel one signature,
    compiled once instead of again on the second frame."""
    view = a.view()
    view.setflags(write=False)
    return view
