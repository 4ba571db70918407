"""Every kernel signature a frame can call, made ready before the first frame needs it.

Takes: the K values and precisions to prepare (by default every compiled variant: K in
objects.STATIC_K and one other K, exact and fast; each with the residual on and off).
Returns: a ``WarmUp`` summary (seconds, kernel signatures loaded from numba's cache and
compiled).

numba compiles a kernel for each new signature on its first call and keeps the machine
code in its cache (``__pycache__`` beside the sources). A frame is the first call of ~30
kernels: on a machine whose cache is empty the first frame of even a 1k-object scene takes
about a minute (bench/RESULTS.md, "cold start"), longer than a client's default timeout,
and one on a warm cache still ~0.2 s of loading, a dozen missed 60 Hz deadlines. A
renderer compiles its shaders before the first frame for the same reason; ``warm_up``
does it here by stepping a small generated city through every path a frame can take
(full, from candidate lists or not, incremental, objects moved, camera moved, nothing
moved, removals, a cut, the caches' compaction, both kinds of object grid) for each K
variant and precision.
Some kernel arguments turn read-only after the first frames (frames are frozen and become
the next frame's state), which is a signature of its own, hence several frames per path.

``kernels`` lists the package's kernels, so that a test (tests/test_warmup.py) can show
that no frame compiles anything once ``warm_up`` ran.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from types import ModuleType

import numpy as np
from numba.core.dispatcher import Dispatcher

from .frame import PER_OBJECT, changed_rows
from .objects import STATIC_K
from .scene import Camera, Config
from .scenes import city, move_lights
from .scheduler import Scheduler
from .tuning import Tuning

# A K compiled without a static trip count (objects.object_pass): any K not in STATIC_K.
GENERIC_K = next(k for k in range(2, 64) if k not in STATIC_K)


@dataclass(frozen=True)
class WarmUp:
    """What ``warm_up`` did: seconds taken, and kernel signatures numba loaded from its
    cache or compiled (over the whole process, so a second call adds nothing)."""

    seconds: float
    loaded: int
    compiled: int

    def summary(self) -> str:
        return (f"kernels ready in {self.seconds:.1f} s: {self.loaded} signatures loaded "
                f"from numba's cache, {self.compiled} compiled")


def kernels(package: ModuleType | None = None) -> dict[str, Dispatcher]:
    """The numba kernels of ``package`` (default lightsched) by qualified name: every
    dispatcher defined in one of its imported modules."""
    name = (package or sys.modules[__package__]).__name__
    found = {}
    for mod_name, module in list(sys.modules.items()):
        if mod_name.startswith(name + ".") and module is not None:
            for obj in vars(module).values():
                if isinstance(obj, Dispatcher) and obj.__module__ == mod_name:
                    found[f"{mod_name}.{obj.__name__}"] = obj
    return found


def cache_counts(package: ModuleType | None = None) -> tuple[int, int]:
    """(signatures loaded from numba's cache, signatures compiled) over the package's
    kernels in this process."""
    loaded = compiled = 0
    for d in kernels(package).values():
        loaded += sum(d.stats.cache_hits.values())
        compiled += sum(d.stats.cache_misses.values())
    return loaded, compiled


def warm_up(max_lights: Iterable[int] | None = None,
            precisions: Sequence[str] = ("exact", "fast")) -> WarmUp:
    """Steps a small city through every frame path for each K in ``max_lights`` (default
    STATIC_K and GENERIC_K), each precision and the residual on and off, so that later
    frames of any scene with those settings load or compile nothing. Leaves no state
    behind but numba's."""
    t = time.perf_counter()
    before = cache_counts()
    for k in (*STATIC_K, GENERIC_K) if max_lights is None else max_lights:
        for precision in precisions:
            # The residual on and off: the object pass is compiled for each (objects.py).
            for residual in (True, False):
                _paths(Config(max_lights=int(k), precision=precision, residual=residual))
    after = cache_counts()
    return WarmUp(time.perf_counter() - t, after[0] - before[0], after[1] - before[1])


def _paths(config: Config) -> None:
    """One scheduler through the frame paths of scheduler.py, with shadowed point, spot
    and directional lights."""
    sc = city(600, 60, seed=1, shadow_fraction=0.3, sun_shadows=True)
    lights, objects = sc.lights, sc.objects
    wide = sc.cameras
    # A camera low in a corner sees few of the objects: the grid of the visible ones and
    # the invisible casters near shadowed lights (Tuning.every_object_share).
    corner = np.array([-0.45 * sc.side, 3.0, -0.45 * sc.side])
    narrow = [Camera(position=corner, forward=np.array([1.0, -0.1, 0.2]),
                     up=np.array([0.0, 1.0, 0.0]), fov_y=0.6, aspect=1.0, near=0.5, far=200.0)]
    # The small city takes the candidate lists' path too (large scenes only, otherwise).
    tuning = Tuning(candidate_min_objects=0)
    s = Scheduler(config, tuning)
    s.set_lights(**lights)
    s.set_objects(**objects)
    ids = lights["id"]
    every, tenth = slice(None), slice(None, None, 10)
    step = 0
    prev = None
    # Full frames from candidate lists: every light drifting keeps or edits them; a third
    # of the lights jumping back and forth edits them until the lists by light are packed.
    for jump in range(10):
        step += 1
        pos = move_lights(lights, step)
        pos[::3, 0] += 4.0 * (jump % 2) if jump > 1 else 0.0
        s.update_lights(id=ids, position=pos)
        s.frame(wide, dt=1 / 60)
    for n_pass, cams in enumerate((wide, narrow, wide)):
        # Its incremental frames copy the rows they keep on the calling thread; in the last
        # pass on every thread (larger scenes do: Tuning.parallel_copy_bytes).
        s.tuning = replace(tuning, parallel_copy_bytes=0 if n_pass == 2
                           else tuning.parallel_copy_bytes)
        # Every light moving (full frames: the second and third from candidate lists),
        # then a tenth (incremental frames, until the pair cache is compacted), then
        # nothing (the frame is kept).
        for moved in (every, every, every, tenth, tenth, tenth, tenth, tenth, tenth, None):
            step += 1
            if moved is not None:
                s.update_lights(id=ids[moved], position=move_lights(lights, step)[moved])
            f = s.frame(cams, dt=1 / 60)
            if prev is not None:
                changed_rows(prev, f, tuple(PER_OBJECT))
            prev = f
        # Objects moved: a few tested against every light, then more against the lights
        # of their cells in a grid of the lights; their records rewritten in the grid of
        # every object.
        for few in (20, 5):
            s.update_objects(id=objects["id"][::few],
                             bounds_min=objects["bounds_min"][::few] + 0.5 / few,
                             bounds_max=objects["bounds_max"][::few] + 0.5 / few)
            s.frame(cams, dt=1 / 60)
        s.frame(cams, dt=1 / 60)
    s.frame(wide, dt=1 / 60, cut=True)
    s.remove_lights(id=ids[:5])
    s.remove_objects(id=objects["id"][:30])
    s.frame(wide, dt=1 / 60)
    s.frame(narrow, dt=1 / 60)
