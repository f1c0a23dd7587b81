"""Time node creation and loop detection on random unit descriptors.

    python benchmarks/bench_loops.py [--dim 256]

Random descriptors are the worst case for the "ours" check only in memory traffic
(every row of the similarity matrix is computed), which is what we want to bound.
"""

from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from engine.loops import detect_loops
from engine.nodes import make_nodes
from engine.params import MapParams


def unit_rows(rng: np.random.Generator, n: int, d: int) -> np.ndarray:
    x = rng.normal(size=(n, d)).astype(np.float32)
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def timed(fn):
    tracemalloc.start()
    t0 = time.perf_counter()
    out = fn()
    dt = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, dt, peak / 1e6


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dim", type=int, default=256)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    # A threshold that random 256-D unit vectors pass now and then (cos std ~ 1/16).
    params = MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.12, window_size=5,
                       count_th=2, neighbor_node_num=5)
    print(f"{'nodes':>7} {'method':>7} {'seconds':>8} {'peak MB':>8} {'loops':>7}")
    for m in (1_000, 5_000, 20_000):
        v = unit_rows(rng, m, args.dim)
        for method in ("ours", "simple"):
            p = MapParams(**{**params.as_dict(), "method": method,
                             "loop_sim_th": 0.12 if method == "ours" else 0.3})
            loops, dt, peak = timed(lambda: detect_loops(v, p))
            print(f"{m:>7} {method:>7} {dt:>8.2f} {peak:>8.1f} {len(loops):>7}")

    # Node creation on a smooth 100k-frame sequence: descriptors blend between random
    # key descriptors 30 frames apart (a robot at 30 fps, about a node a second).
    n, d, gap = 100_000, args.dim, 30
    keys = unit_rows(rng, n // gap + 2, d)
    k = np.arange(n) / gap
    i0 = k.astype(np.int64)
    f = (k - i0)[:, None].astype(np.float32)
    walk = (1 - f) * keys[i0] + f * keys[i0 + 1]
    walk /= np.linalg.norm(walk, axis=1, keepdims=True)
    nodes, dt, peak = timed(lambda: make_nodes(walk, 0.8))
    print(f"make_nodes: {n} rows -> {nodes.size} nodes in {dt:.2f} s (peak {peak:.1f} MB)")
    every = rng.normal(size=(20_000, d)).astype(np.float32)
    every /= np.linalg.norm(every, axis=1, keepdims=True)
    nodes, dt, _ = timed(lambda: make_nodes(every, 0.8))
    print(f"make_nodes: 20000 independent rows -> {nodes.size} nodes in {dt:.2f} s")


if __name__ == "__main__":
    main()
