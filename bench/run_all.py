"""The whole benchmark harness: every bench script with --write, then the summary at the top
of bench/RESULTS.md (the answers each section gives, gathered in one place).

    python bench/run_all.py            # make bench: the full runs (tens of minutes)
    python bench/run_all.py --quick    # make bench-quick: the ~2-minute cut

Each script writes its own generated section of RESULTS.md and its plots in bench/plots/;
a script that fails is reported and the others still run, and the command then exits 1.
A section states its answers on lines that start with "**Answer"; they are copied into the
summary with the section they come from.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path

from common import RESULTS, git_commit, machine, markers, say, write_results

HERE = Path(__file__).resolve().parent
BEGIN, END = markers("run_all.py")
# In the order they run: the quick, self-contained measurements first.
SCRIPTS = ("core.py", "service.py", "scaling.py", "stress.py", "quality.py", "fade_frames.py",
           "peers.py", "load.py")


def sections() -> dict[str, str]:
    """The generated section of each script, as RESULTS.md holds it now."""
    text = RESULTS.read_text() if RESULTS.exists() else ""
    out = {}
    for script in SCRIPTS:
        begin, end = markers(script)
        if begin in text and end in text:
            out[script] = text[text.index(begin):text.index(end)]
    return out


def answers(found: dict[str, str]) -> list[str]:
    lines = []
    for script, body in found.items():
        for line in body.splitlines():
            if line.startswith("**Answer"):
                lines.append(f"- {line} (`bench/{script}`)")
    return lines


def ensure_top(text: str) -> None:
    """Puts the summary's markers right after the title when RESULTS.md has none yet."""
    if BEGIN in text:
        return
    head, _, rest = text.partition("\n")
    RESULTS.write_text(head + "\n\n" + BEGIN + "\n" + END + "\n" + rest)


def render(status: dict[str, str], quick: bool, seconds: float) -> str:
    m = machine()
    cmd = "python bench/run_all.py" + (" --quick" if quick else "")
    found = sections()
    out = [BEGIN, "", "## Summary (`bench/run_all.py`)", "",
           f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit `{git_commit()}` "
           f"in {seconds / 60:.1f} min; {m['cpu']}, {m['nproc']} CPUs, Python {m['python']}, "
           f"numpy {m['numpy']}, numba {m['numba']}.", "",
           "| script | run | section |", "|---|---|---|"]
    for script in SCRIPTS:
        out.append(f"| `bench/{script}` | {status.get(script, 'not run by this command')} | "
                   f"{'below' if script in found else 'missing'} |")
    out += ["", "What the sections below answer:", ""]
    out += answers(found) or ["- (no section states an answer yet)"]
    out += ["", END]
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="the ~2-minute cut (make bench-quick)")
    p.add_argument("--only", nargs="*", default=None,
                   help="run only these scripts (none: just rewrite the summary)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    status: dict[str, str] = {}
    for script in SCRIPTS:
        if args.only is not None and script not in args.only:
            continue
        cmd = [sys.executable, str(HERE / script), "--write"] + (["--quick"] if args.quick else [])
        say(f"\n==== {shlex.join(cmd[1:])}")
        t = time.perf_counter()
        rc = subprocess.run(cmd, cwd=HERE.parent).returncode
        took = time.perf_counter() - t
        status[script] = f"ok in {took:.0f} s" if rc == 0 else f"FAILED (exit {rc}) after {took:.0f} s"
        say(f"==== {script}: {status[script]}")
    ensure_top(RESULTS.read_text() if RESULTS.exists() else "# Benchmark results\n")
    write_results(render(status, args.quick, time.perf_counter() - t0), BEGIN, END)
    failed = [s for s, v in status.items() if not v.startswith("ok")]
    say(f"\nbench: {len(status) - len(failed)} of {len(status)} scripts ok"
        + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
