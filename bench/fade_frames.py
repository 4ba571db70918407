"""Fade, seen: a short run of frames of one city block with and without fade, as a picture.

    python bench/fade_frames.py            # writes bench/plots/fade_frames.png
    python bench/fade_frames.py --write    # also its section of bench/RESULTS.md

The city (lightsched.scenes.city: 3000 boxes, 300 point and spot lights, no sun) with
K = 2, every light moving (scenes.move_lights), a fixed camera, dt = 1/60 s, run twice:
fade off (fade_in = fade_out = 0) and DESIGN's default fade (0.25 s each way); hysteresis
0.1 both times. Each tile is the block from above, every box drawn as its footprint and
shaded by the lighting it is delivered (its slots' lights times their fade weights, summed
over the box's sample points, quality.py's light_at_points) on a log scale. A box outlined
in red pops on that frame: DESIGN section 4's abrupt pop, |(D_t - D_t-1) - (A_t - A_t-1)|
> 0.1 max(A_t, A_t-1), with D delivered and A the lighting of every light that affects the
box, so a change that the lights' own motion explains is not counted. The block and the
frames shown are where the run without fade pops most; both rows show the same frames.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from common import PLOTS, git_commit, machine, markers, say, write_results
from quality import affecting_pairs, face_samples, pair_lighting

import lightsched as ls
from lightsched.scenes import city, move_lights

BEGIN, END = markers("fade_frames.py")
N_OBJECTS, N_LIGHTS, K, FRAMES, DT = 3000, 300, 2, 90, 1 / 60
TILES, STRIDE, BLOCK = 8, 1, 45.0  # frames shown, frames between them, block edge (m)
TRACES = 4  # boxes whose lighting is drawn over the whole run
POP = 0.1  # DESIGN section 4: a one-frame jump over a tenth of the lighting is a pop


@dataclass
class Run:
    """Per frame and object row: delivered lighting D, all-lights lighting A, visibility."""

    name: str
    delivered: np.ndarray
    full: np.ndarray
    visible: np.ndarray

    def pops(self) -> np.ndarray:
        """[frames, objects]: DESIGN section 4's abrupt pops (frame 0 has none)."""
        d, a = self.delivered, self.full
        jump = np.abs((d[1:] - d[:-1]) - (a[1:] - a[:-1]))
        both = self.visible[1:] & self.visible[:-1]
        out = np.zeros_like(self.visible)
        out[1:] = both & (jump > POP * np.maximum(a[1:], a[:-1]))
        return out


def run(config: ls.Config, name: str) -> Run:
    sc = city(N_OBJECTS, N_LIGHTS, seed=1, directional=0)
    s = ls.Scheduler(config)
    s.set_lights(**sc.lights)
    s.set_objects(**sc.objects)
    points, normals = face_samples(s.objects.bounds_min, s.objects.bounds_max)
    n = len(s.objects)
    delivered, full = np.zeros((FRAMES, n)), np.zeros((FRAMES, n))
    visible = np.zeros((FRAMES, n), bool)
    for t in range(FRAMES):
        s.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, t + 1))
        f = s.frame(sc.cameras, dt=DT)
        visible[t] = f.visible
        obj, slot = np.nonzero(f.light_index >= 0)
        lit = pair_lighting(s.lights, points, normals, obj, f.light_index[obj, slot])
        np.add.at(delivered[t], obj, lit * f.fade_weight[obj, slot])
        rows = np.flatnonzero(f.visible)
        lights_seen = np.searchsorted(s.lights.id, f.visible_lights)
        o, lt = affecting_pairs(s.lights, s.objects, rows, lights_seen)
        np.add.at(full[t], o, pair_lighting(s.lights, points, normals, o, lt))
    return Run(name, delivered, full, visible)


def window(pops: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[int, np.ndarray]:
    """The first frame and the block (x0, z0) where the run's pops are most dense."""
    span = (TILES - 1) * STRIDE + 1
    per_start = [pops[t:t + span].sum() for t in range(1, FRAMES - span + 1)]
    first = 1 + int(np.argmax(per_start))
    hit = pops[first:first + span].any(0)
    centre = ((lo + hi) / 2)[:, [0, 2]]
    best, corner = -1, centre[0] - BLOCK / 2
    for c in centre[hit]:
        x0 = c - BLOCK / 2
        inside = np.all((centre >= x0) & (centre <= x0 + BLOCK), axis=1)
        count = int(hit[inside].sum())
        if count > best:
            best, corner = count, x0
    return first, corner


def plot(runs: list[Run], lo: np.ndarray, hi: np.ndarray, first: int, corner: np.ndarray,
         path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    centre = ((lo + hi) / 2)[:, [0, 2]]
    inside = np.flatnonzero(np.all((centre >= corner - 10) & (centre <= corner + BLOCK + 10), 1))
    # Seen from above, the taller box covers the lower: drawn last.
    inside = inside[np.argsort(hi[inside, 1], kind="stable")]
    values = np.concatenate([r.delivered[first:first + TILES * STRIDE, inside].ravel()
                             for r in runs])
    positive = values[values > 0]
    norm = LogNorm(vmin=np.percentile(positive, 2), vmax=np.percentile(positive, 99.5))
    fig = plt.figure(figsize=(2.1 * TILES, 2.4 * len(runs) + 3.2))
    grid = fig.add_gridspec(len(runs) + 1, TILES, height_ratios=[1] * len(runs) + [1.25])
    axes = np.array([[fig.add_subplot(grid[r, c]) for c in range(TILES)]
                     for r in range(len(runs))])
    for row, r in enumerate(runs):
        pops = r.pops()
        for col in range(TILES):
            t = first + col * STRIDE
            ax = axes[row, col]
            boxes = [Rectangle((lo[i, 0], lo[i, 2]), hi[i, 0] - lo[i, 0], hi[i, 2] - lo[i, 2])
                     for i in inside]
            shade = np.maximum(r.delivered[t, inside], norm.vmin)
            coll = PatchCollection(boxes, cmap="inferno", norm=norm)
            coll.set_array(np.where(r.visible[t, inside], shade, np.nan))
            popping = pops[t, inside]
            coll.set_edgecolor(np.where(popping[:, None], [[1, 0.1, 0.1, 1]], [[0, 0, 0, 0]]))
            coll.set_linewidth(np.where(popping, 1.6, 0.0))
            ax.add_collection(coll)
            ax.set_xlim(corner[0], corner[0] + BLOCK)
            ax.set_ylim(corner[1], corner[1] + BLOCK)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_facecolor("#202830")
            ax.set_title(f"frame {t}: {int(popping.sum())} pops", fontsize=8)
            if col == 0:
                ax.set_ylabel(r.name, fontsize=9)
    # The boxes of the block that pop most without fade: their delivered lighting over the
    # run, as a share of what all their lights give (steps are pops, ramps are fades).
    trace = fig.add_subplot(grid[len(runs), :])
    pops0 = runs[0].pops()[:, inside].sum(0)
    shown = inside[np.argsort(-pops0, kind="stable")[:TRACES]]
    frames = np.arange(FRAMES)
    for k, i in enumerate(shown):
        colour = f"C{k}"
        for r, style in zip(runs, ("-", "--"), strict=False):
            share = np.where(r.full[:, i] > 0, r.delivered[:, i] / np.maximum(r.full[:, i], 1e-300),
                             np.nan)
            share[~r.visible[:, i]] = np.nan
            trace.plot(frames, share, style, color=colour, lw=1.3,
                       label=f"box {k + 1}, {r.name}")
    trace.axvspan(first, first + (TILES - 1) * STRIDE, color="0.9", zorder=0)
    trace.set_xlabel("frame (1/60 s); grey: the frames above")
    trace.set_ylabel("delivered / all lights")
    trace.set_ylim(0, 1.05)
    trace.legend(fontsize=7, ncol=TRACES, loc="lower left")
    fig.suptitle(f"City block from above, K = {K}, lights moving, dt 1/60 s: shade = lighting "
                 "delivered (log), red = abrupt pop (DESIGN section 4)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--write", action="store_true", help="write the section of RESULTS.md")
    p.add_argument("--quick", action="store_true",
                   help="the same run (about a minute: run_all.py passes it to every script)")
    args = p.parse_args(argv)
    say(f"running {FRAMES} frames twice (fade off, fade on)")
    runs = [run(ls.Config(max_lights=K, fade_in=0.0, fade_out=0.0), "no fade"),
            run(ls.Config(max_lights=K), "fade 0.25 s")]
    sc = city(N_OBJECTS, N_LIGHTS, seed=1, directional=0)
    s = ls.Scheduler()
    s.set_objects(**sc.objects)  # the rows in ascending id, as the runs have them
    lo, hi = s.objects.bounds_min, s.objects.bounds_max
    first, corner = window(runs[0].pops(), lo, hi)
    path = PLOTS / "fade_frames.png"
    plot(runs, lo, hi, first, corner, path)
    seconds = [r.visible[1:].sum() * DT for r in runs]
    rates = [1000 * r.pops().sum() / sec for r, sec in zip(runs, seconds, strict=True)]
    info = machine()
    section = "\n".join([
        BEGIN, "## Fade, seen: the frames of one city block with and without fade", "",
        f"`python bench/fade_frames.py --write` on {info['cpu']}, commit {git_commit()}: the "
        f"city of {N_OBJECTS} boxes and {N_LIGHTS} lights (no sun), K = {K}, every light "
        f"moving, {FRAMES} frames at 1/60 s; the tiles are frames {first}-"
        f"{first + (TILES - 1) * STRIDE} of a {BLOCK:.0f} m block where the run without fade "
        "pops most. A box's shade is the lighting delivered to it (slots times fade weights, "
        "log scale); red outlines are abrupt pops (DESIGN section 4). Below, the "
        f"{TRACES} boxes of the block that pop most: delivered lighting as a share of all "
        "their lights' over the whole run (solid: no fade, dashed: fade).", "",
        f"![fade frames](plots/{path.name})", "",
        f"**Answer (issue 51):** over the whole run, {rates[0]:.1f} abrupt pops per 1000 "
        f"visible object-seconds without fade, {rates[1]:.1f} with it: a light that loses "
        "its slot dims over 0.25 s instead of vanishing between two frames.",
        END, ""])
    print(section)
    if args.write:
        write_results(section, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
