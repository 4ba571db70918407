"""Client benchmark: the round trip of a 1k-object frame through each client (Python,
TypeScript on Node, C++) over HTTP and, where the client has one, the stream.

    python bench/clients.py                 # 5 rounds of 300 frames per case
    python bench/clients.py --rounds 3 --frames 200
    python bench/clients.py --write         # also writes the table into bench/RESULTS.md

Starts one server per numba target (--targets, default native and avx2: the AVX2 path
forced on an AVX-512 host). Builds the TypeScript client (npm run build) and the C++
client (cmake, into build/cpp) first, and writes the scene (lightsched.scenes.city, 1k
objects and 100 lights, K = 8) to a msgpack file each client's bench program reads. Each
run is one process of one client: a new session, the scene, one frame, 50 warm-up frames,
then timed frames in which every light moves (update_lights with new positions, as a game
sends them), each timed from the update_lights call to the decoded, full frame (all
outputs, msgpack, one kept-alive connection or the session's stream).

Pairing: this 2-core VM drifts by up to 2x between runs a minute apart, so each case runs
right beside a run of the Python client on the same target and transport, the two in
alternating order (ABBA) and the cases rotating round by round. A client's p50 is the
median of its runs' p50s; "vs Python" is the median over rounds of the difference of the
two adjacent runs' p50s (paired, as bench/paired.py compares).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import git_commit, machine, markers, say, write_results
from service import Server

REPO = Path(__file__).resolve().parent.parent
# A server per numba target, each with a cache of its own (as bench/matrix.py keeps them).
CACHE = REPO / "bench" / ".cache" / "matrix"
TS = REPO / "clients" / "typescript"
CPP_BUILD = REPO / "build" / "cpp"
BEGIN, END = markers("clients.py")
N_OBJECTS, N_LIGHTS, K, WARMUP = 1000, 100, 8, 50
# Issue 50: each client's p50 within this of the Python client's on its best transport.
TARGET_MS = 0.3


def write_scene(path: Path, frames: int) -> None:
    from lightsched_client.wire import MSGPACK, dumps

    from lightsched.scenes import city, move_lights

    sc = city(N_OBJECTS, N_LIGHTS, seed=0)
    cam = sc.cameras[0]
    doc: dict[str, Any] = {f"lights.{k}": np.asarray(v) for k, v in sc.lights.items()}
    doc.update({f"objects.{k}": np.asarray(v) for k, v in sc.objects.items()})
    doc["camera"] = np.concatenate([cam.position, cam.forward, cam.up,
                                    [cam.fov_y, cam.aspect, cam.near, cam.far]]).astype(np.float64)
    poses = min(frames, 120)
    doc["positions"] = np.stack([move_lights(sc.lights, i + 1) for i in range(poses)])
    for name, value in (("warmup", WARMUP), ("frames", frames), ("max_lights", K)):
        doc[name] = np.array([value], np.int64)
    path.write_bytes(dumps(doc, MSGPACK))


def run_python(url: str, scene_path: str, transport: str = "http") -> None:
    """The Python client's side (this script run as a child with --run-python)."""
    from lightsched_client import Client
    from lightsched_client.wire import MSGPACK, loads

    import lightsched as ls

    scene = loads(Path(scene_path).read_bytes(), MSGPACK)
    lights = {k[7:]: v for k, v in scene.items() if k.startswith("lights.")}
    objects = {k[8:]: v for k, v in scene.items() if k.startswith("objects.")}
    c = scene["camera"]
    cam = ls.Camera(position=c[0:3], forward=c[3:6], up=c[6:9], fov_y=float(c[9]),
                    aspect=float(c[10]), near=float(c[11]), far=float(c[12]))
    positions = scene["positions"]
    warmup, frames = int(scene["warmup"][0]), int(scene["frames"][0])
    out = []
    with Client(url) as client:
        s = client.session({"max_lights": int(scene["max_lights"][0])},
                           stream=transport == "stream")
        s.set_lights(**lights)
        s.set_objects(**objects)
        s.frame(cam)
        for i in range(warmup + frames):
            t0 = time.perf_counter()
            s.update_lights(id=lights["id"], position=positions[i % len(positions)])
            f = s.frame(cam)
            t = (time.perf_counter() - t0) * 1e3
            assert f.light_ids is not None
            if i >= warmup:
                out.append(t)
        s.close()
    print(json.dumps({"ms": out}))


def commands(url: str, scene: Path) -> dict[tuple[str, str], list[str]]:
    """(client, transport) -> its command. The TypeScript
    client's HTTP runs twice: through the global fetch (what a browser uses) and through
    lightsched/node's nodeFetch (node:http, what a Node program should use)."""
    ts = ["node", "--experimental-websocket", str(TS / "dist" / "bench" / "roundtrip.js"),
          url, str(scene)]
    py = [sys.executable, __file__, "--run-python", url, str(scene)]
    return {("Python", "HTTP"): [*py, "http"],
            ("TypeScript (Node)", "HTTP (fetch)"): [*ts, "http"],
            ("TypeScript (Node)", "HTTP (lightsched/node)"): [*ts, "node"],
            ("C++", "HTTP"): [str(CPP_BUILD / "bench_roundtrip"), url, str(scene), "http"],
            ("C++", "WebSocket"): [str(CPP_BUILD / "bench_roundtrip"), url, str(scene), "stream"],
            ("Python", "WebSocket"): [*py, "stream"],
            ("TypeScript (Node)", "WebSocket"): [*ts, "stream"]}


def _base(transport: str) -> str:
    """The Python client's transport a case is paired with: every HTTP variant with HTTP."""
    return "HTTP" if transport.startswith("HTTP") else transport


def server_env(target: str) -> dict[str, str]:
    """The server's environment for a numba target: "native", or one of
    lightsched.simd.FORCED_TARGETS ("avx2": the AVX2 path on an AVX-512 host)."""
    from lightsched.simd import FORCED_TARGETS

    env = dict(os.environ, NUMBA_CACHE_DIR=str(CACHE / target))
    if target != "native":
        env["NUMBA_CPU_NAME"], env["NUMBA_CPU_FEATURES"] = FORCED_TARGETS[target]
    return env


def build() -> None:
    say("building the TypeScript and C++ clients")
    subprocess.run(["npm", "run", "build"], cwd=TS, check=True, stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "-S", str(REPO / "clients" / "cpp"), "-B", str(CPP_BUILD),
                    "-DCMAKE_BUILD_TYPE=Release"], check=True, stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "--build", str(CPP_BUILD), "-j2", "--target", "bench_roundtrip"],
                   check=True, stdout=subprocess.DEVNULL)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--targets", default="native,avx2",
                   help="the servers' numba targets, comma-separated (default native,avx2)")
    p.add_argument("--write", action="store_true", help="write the section of RESULTS.md")
    p.add_argument("--run-python", nargs=3, metavar=("URL", "SCENE", "TRANSPORT"),
                   help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.run_python:
        run_python(*args.run_python)
        return 0
    build()
    targets = args.targets.split(",")
    say(f"starting a server per target ({', '.join(targets)}); a target's first start "
        "compiles its kernels (minutes)")
    servers = {t: Server(env=server_env(t)) for t in targets}
    p50: dict[tuple[str, str, str], list[float]] = {}
    p99: dict[tuple[str, str, str], list[float]] = {}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            scene = Path(tmp) / "scene.msgpack"
            write_scene(scene, args.frames)
            cmds = {(t, *name): cmd for t, server in servers.items()
                    for name, cmd in commands(server.url, scene).items()}
            cases = [key for key in cmds if key[1] != "Python"]
            paired: dict[tuple[str, str, str], list[float]] = {}

            def run(key: tuple[str, str, str], r: int) -> float:
                done = subprocess.run(cmds[key], capture_output=True, text=True, check=True)
                ms = np.array(json.loads(done.stdout.strip().splitlines()[-1])["ms"])
                p50.setdefault(key, []).append(float(np.median(ms)))
                p99.setdefault(key, []).append(float(np.percentile(ms, 99)))
                say(f"round {r + 1} {key[0]} {key[1]} over {key[2]}: p50 {p50[key][-1]:.3f} ms")
                return p50[key][-1]

            for r in range(args.rounds):
                for i, key in enumerate(cases[r % len(cases):] + cases[:r % len(cases)]):
                    base = (key[0], "Python", _base(key[2]))
                    if (r + i) % 2:
                        own = run(key, r)
                        theirs = run(base, r)
                    else:
                        theirs = run(base, r)
                        own = run(key, r)
                    paired.setdefault(key, []).append(own - theirs)
    finally:
        for server in servers.values():
            server.stop()
    info = machine()
    rows, diffs = [], {}
    for key in cmds:
        target, client, transport = key
        runs = p50[key]
        diffs[key] = float(np.median(paired[key])) if key in paired else 0.0
        rows.append(f"| {target} | {client} | {transport} | {np.median(runs):.3f} | "
                    f"{max(p99[target, client, transport]):.3f} | "
                    f"{diffs[target, client, transport]:+.3f} |")
    answers, missed = [], []
    for target in targets:
        for client in ("TypeScript (Node)", "C++"):
            best = min((d, t) for (g, c, t), d in diffs.items() if (g, c) == (target, client))
            others = [f"{t} {d:+.3f}" for (g, c, t), d in diffs.items()
                      if (g, c) == (target, client) and t != best[1]]
            answers.append(f"{client} on {target} {best[0]:+.3f} ms over {best[1]}"
                           + (f" ({', '.join(others)})" if others else ""))
            if best[0] > TARGET_MS:
                missed.append(f"{client} on {target}")
    section = "\n".join([
        BEGIN, "## Clients: a 1k-object frame's round trip per client", "",
        f"`python bench/clients.py --rounds {args.rounds} --frames {args.frames}` on "
        f"{info['cpu']} ({info['nproc']} cores), commit {git_commit()}: the city of "
        f"{N_OBJECTS} objects and {N_LIGHTS} lights, K = {K}, every light moving; a full "
        "frame over HTTP/msgpack on one kept-alive connection, timed from update_lights to "
        "the decoded frame, each client in its own process against one `lightsched serve`, "
        f"{args.rounds} rounds of {args.frames} frames; each run sits beside a Python run on "
        "the same target and transport, in alternating order.", "",
        "The server runs once per numba target (native; avx2 forces the AVX2 path through "
        "NUMBA_CPU_NAME / NUMBA_CPU_FEATURES), all cases interleaved in one run.", "",
        "| server target | client | transport | p50 ms | p99 ms (worst run) | "
        "p50 vs Python, same target and transport (paired) |",
        "|---|---|---|---|---|---|", *rows, "",
        "**Answer (issue 50):** p50 against the Python client's on the same transport, "
        "each client on its best: " + "; ".join(answers) + ". "
        + (f"Over the {TARGET_MS} ms target: {', '.join(missed)}." if missed
           else f"Every client is within the {TARGET_MS} ms target."),
        END, ""])
    print(section)
    if args.write:
        write_results(section, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
