"""The command line (lightsched/__main__.py): the demo runs and prints a summary."""

from __future__ import annotations

import subprocess
import sys


def test_demo_runs_and_prints_a_summary():
    proc = subprocess.run(
        [sys.executable, "-m", "lightsched", "demo", "--objects", "300", "--lights", "30",
         "--frames", "5"],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert "LightSched demo: 300 objects, 30 lights" in out
    assert "5 frames" in out
    for line in ("visible objects", "visible lights", "mean set size", "milliseconds per frame",
                 "frame() wall time", "plan of the last frame"):
        assert line in out, out


def test_demo_rejects_zero_frames():
    proc = subprocess.run([sys.executable, "-m", "lightsched", "demo", "--frames", "0"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "--frames" in proc.stderr
