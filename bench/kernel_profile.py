"""Where a kernel's time goes, instruction by instruction: a sampling profile of one numba
kernel on the captured inputs of a real frame.

    python bench/kernel_profile.py                         # object_pass, city (10k, 1k), 1 thread
    python bench/kernel_profile.py --kernel group_pairs --size 100k:10k --seconds 8
    python bench/kernel_profile.py --scene dense              # ~33 competing lights an object
    python bench/kernel_profile.py --scene dense --time 30    # only the kernel's median time

The scheduler runs a few full frames on a scene of issue 49's matrix (city by default; every
light moving, as in `bench/matrix.py`); the named kernel's arguments are captured on the last one (every array
is copied before each call, so every call sees the same input). The
kernel is then called in a loop while ``perf record -e cpu-clock`` samples the process:
a software clock, so it works on this VM, which has no hardware counters (``perf stat``
reports cycles "not supported"). The samples' instruction addresses fall in numba's
JIT code, which has no symbols for perf; the pages that hold most samples are read back
from the process and disassembled (objdump), each instruction with its sample count.
Printed: the hottest 128-byte windows of code with their share, and the annotated listing
of each, written to ``--out`` (default /tmp/kernel_profile.txt) in full.

Reading it: a sample lands on the instruction after the one that stalled (skid), so a
store that waits on a chain of compares, or a branch after a load, carries the cost of
what feeds it. Found with it (bench/RESULTS.md): the object pass's rank counting of the
steady slots (a sixth of the pass) and its two passes over each object's pairs.
Needs ``perf`` (Debian ``linux-perf``) and ``objdump`` (binutils); not run by the tests.
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import types
from typing import Any

import numpy as np
from common import SCENE_SPEED, SCENES, make_scene, parse_sizes, say

import lightsched
import lightsched.scheduler  # noqa: F401 - imports every stage's module
from lightsched.scenes import move_lights
from lightsched.tuning import Tuning

WINDOW = 128  # bytes of code per reported window
# Kernels only the candidate lists' frames call (candidates.update_candidates and the pair
# cache made from the lists, pair_cache._from_candidates).
CANDIDATE_KERNELS = ("candidate_pairs", "edit_candidates", "light_lists", "spread_lists",
                     "compact_light_lists", "list_room")


def _code_names(code: types.CodeType) -> set[str]:
    """The global names a function's code (and the functions nested in it) reads."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _code_names(const)
    return names


def callers(kernel: str) -> list[types.ModuleType]:
    """The modules of lightsched whose Python code calls ``kernel`` by that global name
    (the stages call their kernels from Python; a kernel's own calls are compiled in)."""
    found = []
    for name, mod in sorted(sys.modules.items()):
        if not name.startswith("lightsched.") or mod is None or kernel not in vars(mod):
            continue
        funcs = []
        for obj in vars(mod).values():
            if isinstance(obj, type) and obj.__module__ == name:
                funcs += [f for f in vars(obj).values() if isinstance(f, types.FunctionType)]
            elif isinstance(obj, types.FunctionType) and obj.__module__ == name:
                funcs.append(obj)
        if any(kernel in _code_names(f.__code__) for f in funcs):
            found.append(mod)
    return found


def capture(kernel: str, scene_name: str, n_objects: int, n_lights: int,
            frames: int) -> tuple[Any, tuple]:
    """The kernel (as the scheduler's stages call it) and its arguments at its last call,
    on the last of ``frames`` full frames (every light moving) of the named scene.
    Such frames take their pairs from candidate lists from the second on; but for the
    candidate kernels, they are captured with the lists off (Tuning.candidate_lists),
    walking every light as a frame without them does."""
    mods = callers(kernel)
    if not mods:
        raise SystemExit(f"no module of lightsched calls a kernel named {kernel}")
    kern = getattr(mods[0], kernel)
    assert all(getattr(m, kernel) is kern for m in mods), f"{kernel}: two kernels of that name"
    seen: dict[str, tuple] = {}

    def grab(*args):
        seen["args"] = args
        return kern(*args)

    for m in mods:
        setattr(m, kernel, grab)
    try:
        scene = make_scene(scene_name, n_objects, n_lights)
        s = lightsched.Scheduler(lightsched.Config(max_lights=8),
                                 Tuning(candidate_lists=kernel in CANDIDATE_KERNELS))
        s.set_lights(**scene.lights)
        s.set_objects(**scene.objects)
        for i in range(frames):
            s.update_lights(id=scene.lights["id"], position=move_lights(scene.lights, i + 1,
                                                                     speed=SCENE_SPEED[scene_name]))
            s.frame(scene.cameras, dt=1 / 60)
    finally:
        for m in mods:
            setattr(m, kernel, kern)
    if "args" not in seen:
        raise SystemExit(f"{kernel} was not called in a full frame")
    return kern, seen["args"]


def fresh(args: tuple) -> tuple:
    """The arguments with every array copied (tuples of arrays too): the kernel may write
    any of them in place."""
    def copy(x):
        if isinstance(x, np.ndarray):
            return x.copy()
        if isinstance(x, tuple):
            items = [copy(y) for y in x]
            # (A NamedTuple stays one: the kernels read their fields by name.)
            return type(x)(*items) if hasattr(x, "_fields") else tuple(items)
        return x
    return copy(args)


def sample(call, seconds: float, data: str) -> tuple[list[int], int]:
    """Instruction addresses of perf's cpu-clock samples of this process while ``call``
    runs in a loop for ``seconds``, and the number of calls."""
    perf = subprocess.Popen(["perf", "record", "-e", "cpu-clock", "-F", "20000", "-p",
                             str(os.getpid()), "-o", data],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)  # perf attaches
    t0 = time.perf_counter()
    calls = 0
    while time.perf_counter() - t0 < seconds:
        call()
        calls += 1
    perf.send_signal(signal.SIGINT)
    perf.wait()
    out = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True,
                         text=True, check=True).stdout
    return [int(x, 16) for x in out.split()], calls


def listing(ips: list[int], share: float) -> tuple[list[tuple[int, int, str]], int]:
    """(address, samples, instruction) over the adjacent code pages that hold at least
    ``share`` of the samples each and the most in all, disassembled from this process's
    memory; and the samples there."""
    pages = collections.Counter(ip >> 12 for ip in ips)
    hot = sorted(p for p, c in pages.items() if c >= share * len(ips))
    if not hot:
        raise SystemExit("no code page holds enough samples")
    # Runs of adjacent pages (only pages that ran code are read: they are mapped); the run
    # with the most samples is the kernel's (libc's copies and Python are elsewhere).
    runs = [[hot[0]]]
    for p in hot[1:]:
        if p == runs[-1][-1] + 1:
            runs[-1].append(p)
        else:
            runs.append([p])
    best = max(runs, key=lambda r: sum(pages[p] for p in r))
    lo, hi = best[0] << 12, (best[-1] + 1) << 12
    with tempfile.NamedTemporaryFile(suffix=".bin") as f:
        f.write(ctypes.string_at(lo, hi - lo))
        f.flush()
        dis = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64",
                              "--no-show-raw-insn", f"--adjust-vma={lo}", f.name],
                             capture_output=True, text=True, check=True).stdout
    count = collections.Counter(ips)
    rows = []
    for line in dis.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s*(.*)", line)
        if m:
            ad = int(m.group(1), 16)
            rows.append((ad, count.get(ad, 0), m.group(2)))
    return rows, sum(c for ip, c in count.items() if lo <= ip < hi)


def time_calls(a: argparse.Namespace) -> None:
    """The kernel's median time over ``a.time`` calls, each on fresh copies of its inputs
    (the copies untimed). With another commit's lightsched first on PYTHONPATH (and its own
    NUMBA_CACHE_DIR), the same scene times that commit's kernel."""
    (n, n_lights), = parse_sizes(a.size)
    kern, args = capture(a.kernel, a.scene, n, n_lights, a.frames)
    times = []
    for _ in range(a.time + 1):  # the first call is not counted
        fresh_args = fresh(args)
        t0 = time.perf_counter()
        kern(*fresh_args)
        times.append(time.perf_counter() - t0)
    say(f"{a.kernel}, {a.scene} ({a.size}), {os.environ.get('NUMBA_NUM_THREADS', 'all')} "
        f"numba threads, lightsched from {os.path.dirname(lightsched.__file__)}: "
        f"median {np.median(times[1:]) * 1e3:.2f} ms over {a.time} calls")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kernel", default="object_pass",
                    help="a kernel the scheduler's stages call (the name its module calls "
                         "it by)")
    ap.add_argument("--scene", default="city", choices=SCENES)
    ap.add_argument("--size", default="10k:1k", help="N:L of the scene")
    ap.add_argument("--frames", type=int, default=6, help="frames before the capture")
    ap.add_argument("--seconds", type=float, default=5.0, help="sampling time")
    ap.add_argument("--windows", type=int, default=12, help="hottest windows printed")
    ap.add_argument("--out", default=os.path.join(tempfile.gettempdir(),
                                                  "kernel_profile.txt"))
    ap.add_argument("--time", type=int, default=0, metavar="CALLS",
                    help="only time the kernel: the median of CALLS calls (no perf)")
    a = ap.parse_args()
    if a.time:
        return time_calls(a)
    for tool in ("perf", "objdump"):
        if shutil.which(tool) is None:
            raise SystemExit(f"{tool} not found (Debian: linux-perf, binutils)")
    (n, n_lights), = parse_sizes(a.size)
    kern, args = capture(a.kernel, a.scene, n, n_lights, a.frames)
    kern(*fresh(args))  # compiled and warm

    def call():
        kern(*fresh(args))

    with tempfile.TemporaryDirectory() as tmp:
        ips, calls = sample(call, a.seconds, os.path.join(tmp, "perf.data"))
    rows, in_pages = listing(ips, 0.01)
    total = sum(c for _, c, _ in rows) or 1
    say(f"{a.kernel} at ({a.size}), {os.environ.get('NUMBA_NUM_THREADS', 'all')} numba "
        f"threads: {calls} calls, {len(ips)} samples, {in_pages} in the hot code pages "
        "(the rest: copying the inputs, Python, the kernel's helpers elsewhere)")
    windows = collections.Counter()
    for ad, c, _ in rows:
        windows[ad // WINDOW] += c
    acc = 0
    with open(a.out, "w") as f:
        for w, c in windows.most_common(a.windows):
            acc += c
            say(f"  {w * WINDOW:#x}  {c / total:6.1%}  (cumulative {acc / total:6.1%})")
            f.write(f"--- window {w * WINDOW:#x}: {c / total:.1%} of the samples in the "
                    "hot pages\n")
            for ad, n_s, ins in rows:
                if ad // WINDOW == w:
                    f.write(f"{n_s:7d}  {ad & 0xffff:04x}: {ins}\n")
    say(f"annotated windows: {a.out}")


if __name__ == "__main__":
    sys.exit(main())
