"""Every parallel kernel of the core runs only its explicit prange loops in parallel
(lightsched.jit): a bare ``parallel=True`` would turn its whole-array numpy calls into
hidden parallel launches of ~1 us each."""

from __future__ import annotations

import importlib
import pkgutil

from numba.core.registry import CPUDispatcher

import lightsched
from lightsched.jit import prange_only


def _kernels() -> list[tuple[str, CPUDispatcher]]:
    found = []
    for info in pkgutil.iter_modules(lightsched.__path__):
        module = importlib.import_module(f"lightsched.{info.name}")
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.__module__ == module.__name__:
                found.append((f"{module.__name__}.{name}", value))
    return found


def test_parallel_kernels_use_prange_only() -> None:
    kernels = _kernels()
    parallel = [(name, k.targetoptions["parallel"]) for name, k in kernels
                if k.targetoptions.get("parallel")]
    assert len(parallel) >= 20, [name for name, _ in parallel]
    bad = [name for name, option in parallel if option != prange_only()]
    assert not bad, f"parallel kernels not compiled with prange_only(): {bad}"
