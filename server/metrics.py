"""Prometheus text exposition (version 0.0.4) without a client library: frames, per-stage
latency histograms, request latency, sessions, and responses by status."""

from __future__ import annotations

import threading
from bisect import bisect_left
from collections import defaultdict
from typing import Any

# Seconds; a frame stage spans microseconds to tens of milliseconds.
BUCKETS = (0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0)


class Histogram:
    def __init__(self) -> None:
        self.counts = [0] * (len(BUCKETS) + 1)
        self.total = 0.0

    def observe(self, value: float) -> None:
        # The first bucket with value <= bound (le), else +Inf.
        self.counts[bisect_left(BUCKETS, value)] += 1
        self.total += value

    def lines(self, name: str, labels: str) -> list[str]:
        out, run = [], 0
        sep = "," if labels else ""
        for bound, c in zip(BUCKETS, self.counts, strict=False):
            run += c
            out.append(f'{name}_bucket{{{labels}{sep}le="{bound}"}} {run}')
        run += self.counts[-1]
        out.append(f'{name}_bucket{{{labels}{sep}le="+Inf"}} {run}')
        out.append(f"{name}_sum{{{labels}}} {self.total!r}")
        out.append(f"{name}_count{{{labels}}} {run}")
        return out


class Metrics:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.frames = 0
        self.stages: dict[str, Histogram] = defaultdict(Histogram)
        self.requests: dict[tuple[str, int], int] = defaultdict(int)
        self.latency: dict[str, Histogram] = defaultdict(Histogram)

    def observe_frame(self, stats: dict[str, Any]) -> None:
        stages = self.stages
        with self._lock:
            self.frames += 1
            for stage, seconds in stats.get("seconds", {}).items():
                stages[stage].observe(float(seconds))

    def observe_request(self, route: str, status: int, seconds: float) -> None:
        with self._lock:
            self.requests[(route, status)] += 1
            self.latency[route].observe(seconds)

    def render(self, sessions: int) -> str:
        with self._lock:
            out = ["# HELP lightsched_frames_total Frames computed.",
                   "# TYPE lightsched_frames_total counter",
                   f"lightsched_frames_total {self.frames}",
                   "# HELP lightsched_sessions Live sessions.",
                   "# TYPE lightsched_sessions gauge",
                   f"lightsched_sessions {sessions}",
                   "# HELP lightsched_stage_seconds Time per frame stage (frame.stats seconds).",
                   "# TYPE lightsched_stage_seconds histogram"]
            for stage in sorted(self.stages):
                out += self.stages[stage].lines("lightsched_stage_seconds", f'stage="{stage}"')
            out += ["# HELP lightsched_requests_total Responses by route and status.",
                    "# TYPE lightsched_requests_total counter"]
            for (route, status), n in sorted(self.requests.items()):
                out.append(f'lightsched_requests_total{{route="{route}",status="{status}"}} {n}')
            out += ["# HELP lightsched_request_seconds Time from request to response.",
                    "# TYPE lightsched_request_seconds histogram"]
            for route in sorted(self.latency):
                out += self.latency[route].lines("lightsched_request_seconds", f'route="{route}"')
        return "\n".join(out) + "\n"
