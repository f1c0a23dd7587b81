"""Retrieval stage at scale: wall time, CPU time, peak memory and recall of engine.retrieval.

Run one size per process (peak RSS is per process), with two threads:

    OMP_NUM_THREADS=2 OPENBLAS_NUM_THREADS=2 PYTHONPATH=$PWD \\
        python benchmarks/bench_retrieval.py --n 100000 --method approximate

Data: ``benchmarks.harness.random_walk_descriptors(n, 1024, seed)`` (a smooth walk on the
sphere with forward and reverse revisits), or ``--synthetic`` for the descriptors of a
rendered synthetic recording (``benchmarks.harness.describe_case``; small n, for recall on
real descriptor statistics). Times: ``nearest`` (k=10, exclude=5) and ``background``.
Recall@k of the approximate path is measured against exact search for a random sample of
query rows (exact for a few thousand rows costs rows * n * d, cheap at any n).

Peak RSS is ru_maxrss of this process (includes the descriptors themselves: 400 MB at
100k x 1024-D float32). CPU time (user + system) is reported beside wall time because the
development machine is shared: wall time there varies with the load of other processes.

faiss-cpu 1.15.1 was tried as the approximate path first (20k x 1024-D, 2 threads, loaded
machine): IVF-flat search took 5.1 s at nprobe 8 and 11.6 s at nprobe 16 (it scans cells
query by query, without BLAS), HNSW (M 16, efConstruction 40) took 5.7 s to build and
1.6 s to search: slower than the numpy inverted file, so no dependency was added.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine import retrieval  # noqa: E402
from benchmarks.harness import random_walk_descriptors  # noqa: E402


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def exact_rows(v: np.ndarray, rows: np.ndarray, k: int, exclude: int) -> np.ndarray:
    """Exact top-k indices of the given query rows (brute force on those rows only)."""
    sims = v[rows] @ v.T
    near = np.abs(rows[:, None] - np.arange(v.shape[0])[None, :]) <= exclude
    sims[near] = -np.inf
    return np.argsort(-sims, axis=1)[:, :k]


def recall_at_k(found: np.ndarray, truth: np.ndarray) -> float:
    return float(np.mean([len(set(f) & set(t)) / len(t) for f, t in zip(found, truth)]))


def revisits_found(neigh, origin: np.ndarray, tolerance: int = 2) -> float:
    """Share of revisiting rows with a neighbour within ``tolerance`` rows of the row they revisit."""
    rows = np.flatnonzero(origin >= 0)
    idx = neigh.index[rows]
    near = (np.abs(idx - origin[rows][:, None]) <= tolerance) & (idx >= 0)
    return float(np.mean(near.any(axis=1))) if rows.size else float("nan")


def synthetic_vectors() -> np.ndarray:
    from benchmarks.harness import Case, describe_case

    d = describe_case(Case("figure8", "city", seed=0), shifts=(True,))
    return d.by_shift[True].vectors


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--d", type=int, default=1024)
    ap.add_argument("--k", type=int, default=10)
    ap.add_argument("--exclude", type=int, default=5)
    ap.add_argument("--method", default="auto", choices=retrieval.METHODS)
    ap.add_argument("--nprobe", type=int, default=None, help="approximate path: cells per query")
    ap.add_argument("--recall-rows", type=int, default=2000)
    ap.add_argument("--synthetic", action="store_true", help="descriptors of a rendered recording")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    origin = None
    if args.synthetic:
        v = synthetic_vectors()
    else:
        v, origin = random_walk_descriptors(args.n, args.d, args.seed)
    n, d = v.shape
    if args.nprobe is not None:
        retrieval.NPROBE = args.nprobe
    base_mb = _peak_mb()
    method = retrieval.choose_method(n, d) if args.method == "auto" else args.method

    w0, c0 = time.perf_counter(), _cpu()
    neigh = retrieval.nearest(v, args.k, args.exclude, method=args.method)
    w1, c1 = time.perf_counter(), _cpu()
    stats = retrieval.background(v, args.exclude)
    z = retrieval.calibrated(neigh, stats)
    w2, c2 = time.perf_counter(), _cpu()
    peak = _peak_mb()

    rng = np.random.default_rng(1)
    rows = np.sort(rng.choice(n, min(n, args.recall_rows), replace=False))
    truth = exact_rows(v, rows, args.k, args.exclude)
    out = {
        "n": n, "d": d, "k": args.k, "exclude": args.exclude, "method": method,
        "nprobe": retrieval.NPROBE if method == "approximate" else None,
        "threads": os.environ.get("OMP_NUM_THREADS", ""),
        "nearest_wall_s": round(w1 - w0, 2), "nearest_cpu_s": round(c1 - c0, 2),
        "background_wall_s": round(w2 - w1, 2), "background_cpu_s": round(c2 - c1, 2),
        "peak_rss_mb": round(peak), "rss_before_mb": round(base_mb),
        "recall_at_k": round(recall_at_k(neigh.index[rows], truth), 4),
        "revisits_found": None if origin is None else round(revisits_found(neigh, origin), 4),
        "median_top_z": round(float(np.nanmedian(z[:, 0])), 2),
        "load_avg_1min": round(os.getloadavg()[0], 1),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
