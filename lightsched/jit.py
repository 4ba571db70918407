"""Compile options shared by the parallel kernels.

numba's ``parallel=True`` also turns whole-array numpy calls inside a kernel (``np.zeros``,
``np.full``, ``a.sum()``, ``a.max()``, ``a[:] = x``) into parallel loops of their own, and
each one, however small, wakes the second thread and waits for it, which can cost more
than a small kernel's whole work (bench/RESULTS.md, "Measurements behind the code"). The
kernels say where they want both cores, with ``prange``; ``PRANGE_ONLY``
keeps everything else on the calling thread.
"""

from __future__ import annotations

from numba.core.cpu import ParallelOptions

# numba's ``parallel`` option with only explicit ``prange`` loops run in parallel (no
# conversion of numpy calls, array expressions, in-place operators or reductions on arrays,
# and no fusion of adjacent loops, so each prange runs as written). A ParallelOptions, not
# the dict numba documents: numba reads a dict by popping its keys when it compiles a
# kernel's first signature, so every later signature found it empty and was compiled with
# every conversion on (each key's default). A ParallelOptions is copied, so one serves all.
PRANGE_ONLY = ParallelOptions({"prange": True, "comprehension": False, "reduction": False,
                               "inplace_binop": False, "setitem": False, "numpy": False,
                               "stencil": False, "fusion": False})

# How the parallel kernels split their work: objects per work item (the object pass, the
# records, the candidates), and the independent runs of a counting sort (each with its own
# histogram) when grouping pairs or ordering objects by cell.
OBJECT_CHUNK = 256
GROUP_PARTS = 2
