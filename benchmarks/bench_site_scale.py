"""Time ``panotopo map`` of a site of many recordings from cached descriptors.

    python benchmarks/bench_site_scale.py                      # 10 recordings x 3,600 rows
    python benchmarks/bench_site_scale.py --recordings 4 --rows 1000 --dim 256

Descriptors: one ``benchmarks.harness.random_walk_descriptors`` walk of recordings x rows
(d = 256 by default), cut into ``--recordings`` consecutive .npz files (each its own clock
from 0): the walk's revisits of earlier stretches become revisits within a recording or,
where the earlier stretch lies in an earlier file, across recordings. No local features (a
random walk has no pictures): the verified method maps without two-view geometry and pose
graph, so this measures the site's own cost (loading, concatenating, nodes per recording,
calibration, retrieval over all nodes, support, places, tiers, the map and its GraphML).

The map is made by the command line in a child process (``python -m engine map ...``), as a
user would; the child's wall time and peak resident memory (``getrusage`` of children) are
reported, with the node and loop counts and how many of the revisits across recordings have
a loop (a loop whose ends' first visits are within ``--tolerance`` rows: a place driven three times
is one place). Then one more
recording is added to the written site (``map site.graphml NEW.npz``), timed the same way.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from benchmarks.harness import random_walk_descriptors  # noqa: E402
from engine.descriptors.base import Descriptors  # noqa: E402


def _save(path: Path, v: np.ndarray) -> None:
    n = v.shape[0]
    Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                shifts=np.zeros(n, np.int64), vectors=v,
                meta={"descriptor": "random-walk", "shift": True, "interval": 1.0}).save(path)


def _timed(cmd: list[str]) -> tuple[float, float, str]:
    """(wall seconds, peak RSS of the child in MB, stderr) of one child process.

    The child's own peak (``os.wait4``), after this process freed what it read: a child
    forked from a large parent counts the parent's pages until it execs (the networkx graph
    ``_score`` read made an 11th recording's map look 4.6 GB instead of 2.8)."""
    import gc
    import os

    gc.collect()
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        child = subprocess.Popen(cmd, stdout=err, stderr=subprocess.STDOUT, text=True)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        err.seek(0)
        text = err.read()
    if child.returncode != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{text[-2000:]}")
    return wall, usage.ru_maxrss / 1024.0, text   # KB on Linux


def _score(graphml: Path, origin: np.ndarray, rows: int, tolerance: int) -> dict:
    import networkx as nx

    g = nx.read_graphml(graphml)
    names = [r["session"] for r in json.loads(g.graph["sessions"])]
    rec = {name: k for k, name in enumerate(names)}
    row = {n: rec[d["session"]] * rows + int(d["frame"]) for n, d in g.nodes(data=True)}
    loops = [(row[u], row[v]) for u, v, d in g.edges(data=True) if d["kind"] == "loop"]
    cross = [(a, b) for a, b in loops if a // rows != b // rows]
    n = origin.size
    root = np.arange(n)
    for i in np.flatnonzero(origin >= 0):   # the first visit of a place revisited more than once
        root[i] = root[origin[i]]
    revisit = np.flatnonzero((origin >= 0) & (np.arange(n) // rows != np.maximum(origin, 0) // rows))
    hit = np.zeros(n, bool)
    true_cross = 0
    for a, b in cross:
        lo, hi = min(a, b), max(a, b)
        ok = abs(int(root[hi]) - int(root[lo])) <= tolerance
        true_cross += bool(ok)
        hit[max(0, hi - tolerance):hi + tolerance + 1] |= ok
    # revisit events across recordings: runs of consecutive revisit rows
    events = np.split(revisit, np.flatnonzero(np.diff(revisit) > 1) + 1) if revisit.size else []
    found = sum(1 for e in events if hit[e].any())
    return {"nodes": g.number_of_nodes(), "loops": len(loops), "cross_loops": len(cross),
            "cross_loops_true": true_cross, "cross_revisit_stretches": len(events), "found": found}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recordings", type=int, default=10)
    ap.add_argument("--rows", type=int, default=3600, help="rows (about nodes) per recording")
    ap.add_argument("--dim", type=int, default=256)
    ap.add_argument("--tolerance", type=int, default=5, help="rows a loop may miss the true origin by")
    ap.add_argument("--keep", help="folder for the .npz files and maps (default: a temporary one)")
    args = ap.parse_args()

    root = Path(args.keep or tempfile.mkdtemp(prefix="site_scale_"))
    root.mkdir(parents=True, exist_ok=True)
    k, rows = args.recordings, args.rows
    t0 = time.perf_counter()
    v, origin = random_walk_descriptors((k + 1) * rows, args.dim, seed=0)
    files = []
    for i in range(k + 1):
        files.append(root / f"rec{i:02d}.npz")
        _save(files[-1], v[i * rows:(i + 1) * rows])
    print(f"{k} recordings x {rows:,} rows (+1 to add), d={args.dim}: descriptors in {time.perf_counter() - t0:.1f} s "
          f"({root})")

    site = root / "site.graphml"
    cmd = [sys.executable, "-m", "engine", "map", *map(str, files[:k]), "-o", str(site)]
    wall, peak, text = _timed(cmd)
    score = _score(site, origin[:k * rows], rows, args.tolerance)
    print(f"map of {k} recordings: {wall:.1f} s wall, peak RSS {peak:,.0f} MB; {score}")
    for line in text.splitlines():
        if line.startswith(("warning", "wrote")):
            print("   ", line.strip()[-300:])

    site2 = root / "site2.graphml"
    wall2, peak2, text2 = _timed([sys.executable, "-m", "engine", "map", str(site), str(files[k]), "-o", str(site2)])
    score2 = _score(site2, origin, rows, args.tolerance)
    print(f"adding recording {k + 1}: {wall2:.1f} s wall, peak RSS {peak2:,.0f} MB; {score2}")


if __name__ == "__main__":
    main()
