"""Time the paper's "ours" loop check on random-walk descriptors of many nodes.

    python benchmarks/bench_ours_scale.py --nodes 50000
    python benchmarks/bench_ours_scale.py --nodes 200000 --tiles 300   # first 300 tiles, extrapolated

Descriptors: ``benchmarks.harness.random_walk_descriptors`` (d = 256 by default), every row a
node (as a .npz mapped with a node threshold that merges nothing); loop_sim_th calibrated
from the rows as ``panotopo map`` does for a descriptor it does not know
(``engine.calibrate.paper_thresholds``). The check's cost is that of all m^2 / 2
similarities, computed tile by tile; ``--tiles N`` stops after N tiles (through the cancel
token) and extrapolates the whole from the time per tile (every tile but the last row's
is the same size), so that 200,000 nodes can be timed in a few minutes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from benchmarks.harness import random_walk_descriptors  # noqa: E402
from engine.calibrate import paper_thresholds  # noqa: E402
from engine.errors import Cancelled  # noqa: E402
from engine.loops import detect_loops  # noqa: E402
from engine.params import MapParams  # noqa: E402


class _StopAfter:
    """A cancel token set once ``tiles`` tiles are done (fed by the progress callback)."""

    def __init__(self, tiles: int):
        self.tiles, self.done, self.total = tiles, 0, 0

    def progress(self, done: int, total: int, stage: str) -> None:
        self.done, self.total = done, total

    def is_set(self) -> bool:
        return self.tiles > 0 and self.done >= self.tiles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nodes", type=int, default=50_000)
    ap.add_argument("--dim", type=int, default=256)
    ap.add_argument("--tiles", type=int, default=0, help="stop after this many tiles and extrapolate (0: all)")
    args = ap.parse_args()

    t0 = time.perf_counter()
    v, _ = random_walk_descriptors(args.nodes, args.dim, seed=0)
    th = paper_thresholds(v, MapParams().neighbor_node_num)
    print(f"{args.nodes:,} nodes, d={args.dim}: descriptors and thresholds in {time.perf_counter() - t0:.1f} s "
          f"(loop_sim_th {th['loop_sim_th']:.3f})")
    params = MapParams(method="ours", node_sim_th=th["node_sim_th"], loop_sim_th=th["loop_sim_th"])
    stop = _StopAfter(args.tiles)
    t0 = time.perf_counter()
    try:
        loops = detect_loops(v, params, progress=stop.progress, cancel=stop)
        dt = time.perf_counter() - t0
        print(f"ours: {len(loops):,} loops in {dt:.1f} s ({stop.total:,} tiles, {dt / max(stop.total, 1):.3f} s each)")
    except Cancelled:
        dt = time.perf_counter() - t0
        per = dt / max(stop.done, 1)
        print(f"ours: {stop.done:,} of {stop.total:,} tiles in {dt:.1f} s ({per:.3f} s each): "
              f"all of them about {per * stop.total:.0f} s ({per * stop.total / 60:.1f} min)")


if __name__ == "__main__":
    main()
