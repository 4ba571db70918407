"""Core frame time across commits: the working tree's bench/core.py against each commit's core.

    python bench/history.py HEAD~1 HEAD                      # 10k:1k and 100k:10k, every scenario
    python bench/history.py --sizes 10k:1k --scenarios full,static --runs 1 --frames 3 HEAD HEAD~1
    python bench/history.py --json history.json 69fc4f3 HEAD WORKTREE

Each commit's ``lightsched/`` is extracted with ``git archive <commit> lightsched | tar -x``
into a temporary folder (``--workdir`` to keep it, and the numba cache in it, between calls),
and the current ``bench/core.py`` runs against it with ``PYTHONPATH=<folder>`` (the name
``WORKTREE`` means the working tree's ``lightsched/`` as it is now). Every run is a fresh
process doing one run of each (scenario, size); the commits are interleaved run by run
(A B A B ...) so that their ratios come from the same minutes. The scenes come from each
commit's own ``lightsched.scenes`` (seeded; ``city`` has not changed since it was written),
and bench/core.py uses only the public API, so older commits work as long as they have
``lightsched.scenes``; a commit whose run fails is reported with its error and skipped.

Prints a markdown table: commit | subject | median ms per (scenario, size) (the median of the
run medians; in brackets the ratio to the first commit). ``--json PATH`` keeps every run.
Nothing is written to RESULTS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import fmt_count, machine, parse_sizes, say

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CORE = HERE / "core.py"
WORKTREE = "WORKTREE"


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                          check=True).stdout.strip()


def resolve(name: str) -> dict[str, str]:
    """{name, sha, subject} of a commit-ish, or of the working tree."""
    if name == WORKTREE:
        return {"name": name, "sha": WORKTREE, "subject": "(the working tree as it is now)"}
    try:
        sha = git("rev-parse", "--verify", "--quiet", f"{name}^{{commit}}")
    except subprocess.CalledProcessError:
        raise SystemExit(f"history.py: {name!r} is not a commit") from None
    return {"name": name, "sha": sha, "subject": git("log", "-1", "--format=%s", sha)}


def extract(commit: dict[str, str], workdir: Path) -> Path:
    """The folder to put on PYTHONPATH for ``commit``: its lightsched/ extracted there."""
    if commit["sha"] == WORKTREE:
        return ROOT
    dest = workdir / commit["sha"][:12]
    if not (dest / "lightsched" / "__init__.py").exists():
        dest.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", commit["sha"], "lightsched"], cwd=ROOT,
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest


def run_once(commit: dict[str, str], path: Path, args: argparse.Namespace, out: Path
             ) -> tuple[dict[str, Any] | None, str]:
    """One process of bench/core.py against ``path``: (its JSON, "") or (None, the error)."""
    upto = max(n for n, _ in parse_sizes(args.sizes))
    cmd = [sys.executable, str(CORE), "--sizes", args.sizes, "--scenarios", args.scenarios,
           "--runs", "1", "--frames", str(args.frames), "--warmup", str(args.warmup),
           "--incremental-up-to", str(upto), "--shadow-budgets", "none", "--compare", "none",
           "--seed", str(args.seed), "--json", str(out)]
    env = dict(os.environ)
    env["PYTHONPATH"] = str(path) + (os.pathsep + env["PYTHONPATH"]
                                     if env.get("PYTHONPATH") else "")
    out.unlink(missing_ok=True)
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if p.returncode != 0 or not out.exists():
        lines = (p.stderr or p.stdout).strip().splitlines() or [f"exit {p.returncode}"]
        return None, lines[-1]
    doc = json.loads(out.read_text())
    want = str(Path(path, "lightsched").resolve())
    if doc.get("lightsched") != want:  # e.g. an import hook that wins over PYTHONPATH
        return None, f"imported lightsched from {doc.get('lightsched')}, not {want}"
    return doc, ""


def key(r: dict[str, Any]) -> str:
    return f"{r['scenario']} {fmt_count(r['n'])}:{fmt_count(r['l'])}"


def median(xs: list[float]) -> float:
    s = sorted(xs)
    m = len(s) // 2
    return s[m] if len(s) % 2 else 0.5 * (s[m - 1] + s[m])


def table(commits: list[dict[str, Any]], keys: list[str]) -> str:
    def cell(c: dict[str, Any], k: str) -> str:
        got = c["summary"].get(k)
        if got is None:
            return "failed" if c["errors"] else "-"
        base = commits[0]["summary"].get(k)
        ratio = f" ({got['median'] / base['median']:.2f}x)" if base and c is not commits[0] \
            and base["median"] > 0 else ""
        return f"{got['median']:.3g}{ratio}"

    head = ["commit", "subject", *[f"{k} ms" for k in keys]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in commits:
        sha = c["sha"][:9] if c["sha"] != WORKTREE else WORKTREE
        subject = c["subject"] if len(c["subject"]) <= 60 else c["subject"][:57] + "..."
        lines.append("| " + " | ".join([f"`{sha}`", subject.replace("|", "\\|"),
                                        *[cell(c, k) for k in keys]]) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("commits", nargs="+",
                   help=f"commits to compare (anything git rev-parse takes; {WORKTREE}: the "
                        "working tree), the first is the base of the ratios")
    p.add_argument("--sizes", default="10k:1k,100k:10k",
                   help="N:L pairs passed to core.py (default 10k:1k,100k:10k); every "
                        "scenario runs at every size")
    p.add_argument("--scenarios", default="full,static,lights10,camera,objects1",
                   help="scenarios passed to core.py (default all)")
    p.add_argument("--runs", type=int, default=3, help="runs per commit (default 3)")
    p.add_argument("--frames", type=int, default=20, help="timed frames per run (default 20)")
    p.add_argument("--warmup", type=int, default=3,
                   help="warm-up frames (default 3; core.py uses at least 20 for scenarios "
                        "other than full)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workdir", default=None,
                   help="folder for the extracted commits (kept; default a temporary folder, "
                        "removed at the end)")
    p.add_argument("--json", default=None, metavar="PATH", help="dump every run as JSON")
    args = p.parse_args(argv)
    parse_sizes(args.sizes)  # fail early on a bad size
    if args.runs < 1 or args.frames < 1 or args.warmup < 1:
        p.error("--runs, --frames and --warmup must be >= 1")

    commits: list[dict[str, Any]] = [resolve(c) for c in args.commits]
    tmp = Path(tempfile.mkdtemp(prefix="lightsched-history-"))
    workdir = Path(args.workdir).resolve() if args.workdir else tmp
    m = machine()
    say(f"{m['cpu']}, {m['nproc']} CPUs, numba {m['numba']}; sizes {args.sizes}, scenarios "
        f"{args.scenarios}, {args.runs} runs x {args.frames} frames per commit")
    t0 = time.perf_counter()
    try:
        for c in commits:
            c.update(path=str(extract(c, workdir)), runs=[], errors=[])
        for run in range(args.runs):
            for i, c in enumerate(commits):
                doc, err = run_once(c, Path(c["path"]), args, tmp / f"run-{i}.json")
                if doc is None:
                    c["errors"].append(err)
                    say(f"run {run + 1} {c['name']}: failed: {err}")
                    continue
                c["runs"].append(doc)
                load = "/".join(f"{x:.1f}" for x in doc.get("load", []))
                say(f"run {run + 1} {c['name']}: " + ", ".join(
                    f"{key(r)} {r['median']:.3g} ms" for r in doc["results"])
                    + f" (load average {load})")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    keys: list[str] = []
    for c in commits:
        per: dict[str, list[float]] = {}
        plans: dict[str, dict[str, str]] = {}
        for doc in c["runs"]:
            for r in doc["results"]:
                per.setdefault(key(r), []).append(r["median"])
                plans[key(r)] = r["plan"]
                if key(r) not in keys:
                    keys.append(key(r))
        c["summary"] = {k: {"median": median(v), "run_ms": v, "plan": plans[k]}
                        for k, v in per.items()}
    say(f"\n{args.runs} runs per commit, interleaved, in {time.perf_counter() - t0:.0f} s; "
        "median ms of the run medians (x: ratio to the first commit)\n")
    say(table(commits, keys))
    for c in commits:
        if c["errors"]:
            say(f"\n{c['name']}: {len(c['errors'])} failed runs; last error: {c['errors'][-1]}")
    if args.json:
        doc = {"argv": sys.argv[1:], "machine": m,
               "commits": [{k: v for k, v in c.items() if k != "path"} for c in commits]}
        Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
        say(f"\nwrote {args.json}")
    return 0 if all(c["runs"] for c in commits) else 1


if __name__ == "__main__":
    sys.exit(main())
