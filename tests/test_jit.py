"""Every parallel kernel of the core runs only its explicit prange loops in parallel
(lightsched.jit), for every signature it is compiled for: a bare ``parallel=True`` would
turn its whole-array numpy calls into hidden parallel launches of ~1 us each."""

from __future__ import annotations

import importlib
import pkgutil

import numba as nb
import numpy as np
from numba.core.registry import CPUDispatcher

import lightsched
from lightsched.jit import PRANGE_ONLY


def _kernels() -> list[tuple[str, CPUDispatcher]]:
    found = []
    for info in pkgutil.iter_modules(lightsched.__path__):
        module = importlib.import_module(f"lightsched.{info.name}")
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.__module__ == module.__name__:
                found.append((f"{module.__name__}.{name}", value))
    return found


def test_parallel_kernels_use_prange_only() -> None:
    parallel = [(name, k.targetoptions["parallel"]) for name, k in _kernels()
                if "parallel" in k.targetoptions]
    assert len(parallel) >= 20, [name for name, _ in parallel]
    bad = [name for name, option in parallel if option != PRANGE_ONLY]
    assert not bad, f"parallel kernels not compiled with PRANGE_ONLY: {bad}"


def _zero_then_fill(a):
    z = np.zeros(a.shape[0])
    for i in nb.prange(a.shape[0]):
        z[i] = a[i]
    return z


def _parallel_loops(kernel) -> list[int]:
    """Per compiled signature, the parallel loops numba made of the kernel."""
    return [len(kernel.get_metadata(sig)["parfor_diagnostics"].initial_parfors)
            for sig in kernel.signatures]


def test_prange_only_holds_for_every_signature() -> None:
    """Every signature of a kernel is compiled with the options of the first: numba
    consumed a dict option then, and the next signatures turned np.zeros into a parallel
    loop of its own (the count the bare parallel=True gives, checked alongside)."""
    arrays = [np.arange(5, dtype=dtype) for dtype in (np.float64, np.float32, np.int64)]
    kernel = nb.njit(parallel=PRANGE_ONLY)(_zero_then_fill)
    every = nb.njit(parallel=True)(_zero_then_fill)
    for a in arrays:
        np.testing.assert_array_equal(kernel(a), np.arange(5.0))
        every(a)
    assert _parallel_loops(kernel) == [1, 1, 1]
    assert _parallel_loops(every) == [2, 2, 2]
