"""Mapping at scale: ``panotopo map`` of a foreign 100k x 1,024-D descriptors file, and
re-mapping 5,000 nodes after a threshold change (issue 13, item 6).

    python benchmarks/bench_scale.py [--nodes 100000] [--dim 1024] [--remap-nodes 5000]

The descriptors are a random walk on the sphere with revisits
(``benchmarks.harness.random_walk_descriptors``), saved as a ``.npz`` whose ``meta`` names a
descriptor panotopo does not know ("my-own-vpr"), with no column signatures and no local
features: thresholds come from the recording. ``panotopo map`` runs as a child process with
two BLAS threads; wall time and the child's peak resident memory are reported.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.harness import random_walk_descriptors  # noqa: E402
from engine.descriptors.base import Descriptors  # noqa: E402
from engine.params import MapParams  # noqa: E402
from engine.pipeline import build_map  # noqa: E402


def foreign_npz(path: Path, n: int, dim: int) -> None:
    v, _ = random_walk_descriptors(n, dim, seed=0)
    d = Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                    shifts=np.zeros(n, np.int64), vectors=v.astype(np.float32),
                    meta={"descriptor": "my-own-vpr", "shift": True})
    d.save(path)


def map_child(npz: Path, out: Path) -> tuple[float, float, int]:
    env = dict(os.environ, OMP_NUM_THREADS="2", OPENBLAS_NUM_THREADS="2")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "gui.cli", "map", str(npz), "-o", str(out),
                           "--node-sim-th", "0.99999", "-q"], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    rss_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    import networkx as nx

    g = nx.read_graphml(out)
    return wall, rss_mb, g.number_of_nodes()


def remap(n: int, dim: int) -> tuple[float, float]:
    v, _ = random_walk_descriptors(n, dim, seed=1)
    d = Descriptors(np.arange(n, dtype=float), np.arange(n), np.zeros(n, np.int64), v.astype(np.float32),
                    {"descriptor": "my-own-vpr", "shift": True})
    p = MapParams(node_sim_th=0.99999)
    t0 = time.perf_counter()
    build_map(d, p)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    build_map(d, MapParams(node_sim_th=0.99999, candidate_z=p.candidate_z + 0.5, auto_support=p.auto_support + 0.5))
    return first, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nodes", type=int, default=100_000)
    ap.add_argument("--dim", type=int, default=1024)
    ap.add_argument("--remap-nodes", type=int, default=5000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        npz = Path(tmp) / "foreign.npz"
        foreign_npz(npz, args.nodes, args.dim)
        wall, rss, nodes = map_child(npz, Path(tmp) / "map.graphml")
    first, again = remap(args.remap_nodes, args.dim)
    rows = [("`panotopo map` foreign .npz", f"{nodes:,} nodes x {args.dim}-D", f"{wall:.1f} s", f"{rss:,.0f} MB"),
            ("build_map, first time", f"{args.remap_nodes:,} nodes", f"{first:.2f} s", ""),
            ("build_map after a threshold change (cached)", f"{args.remap_nodes:,} nodes", f"{again:.2f} s", "")]
    print("| what | size | time | peak memory |\n|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    print(json.dumps({"map_wall_s": wall, "map_peak_rss_mb": rss, "nodes": nodes,
                      "remap_first_s": first, "remap_cached_s": again}))


if __name__ == "__main__":
    main()
