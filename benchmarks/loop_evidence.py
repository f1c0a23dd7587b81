"""The evidence of ``verified``'s loops against ground truth, per family (development tool).

    python benchmarks/loop_evidence.py --family first --seeds 0,1,2,3,4 --cache C [--key plane_share]

For every automatic loop and every candidate of the maps of described recordings (from
bench_families.py's cache), whether its two nodes are within 1 m of each other (the
evaluation's same-place radius), and the distribution of one evidence attribute for the
right and the wrong ones: where a threshold on it could go (``plane_share`` for stage 7's
plane rule; ``closure_ratio``, closure over stage 9's tolerance, for stage 9).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_families as bf  # noqa: E402
from engine.loop_closure import reckoning_tolerance  # noqa: E402
from engine.params import MapParams  # noqa: E402
from engine.run import run as run_map  # noqa: E402

SAME_PLACE_M = 1.0


def loop_rows(recordings, params: MapParams):
    """(status, metres apart, evidence dict with closure_ratio added) of every loop."""
    for case, descs, poses, _fps in recordings:
        topomap = run_map(descs, params).topomap
        nodes = topomap.graph.nodes
        for u, w, attrs in topomap.loops(("auto", "candidate")):
            x, y = poses.at(np.array([nodes[u]["stamp"], nodes[w]["stamp"]]))
            a, b = sorted((int(nodes[u]["index"]), int(nodes[w]["index"])))
            tolerance = reckoning_tolerance(b - a, params)
            closure = attrs.get("closure")
            evidence = dict(attrs, closure_ratio=None if closure is None else closure / tolerance)
            yield attrs.get("status"), float(np.hypot(x[1] - x[0], y[1] - y[0])), evidence


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", choices=("first", "second"), default="first")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--cache", default="/tmp/panotopo-families")
    ap.add_argument("--key", default="plane_share")
    args = ap.parse_args()
    bf.PHOTOMETRIC["value"] = bf.photometric_for("verified")   # the descriptors verified asks for
    gen = bf.first_family if args.family == "first" else bf.second_family
    rows = list(loop_rows(gen([int(s) for s in args.seeds.split(",")], Path(args.cache)), MapParams()))
    print(f"{args.key} of {args.family} family seeds {args.seeds} (right: ends within {SAME_PLACE_M:g} m)\n")
    print("| tier | loops | right / wrong | right: min / median / max | wrong: min / median / max |")
    print("|---|---:|---:|---|---|")
    for tier in ("auto", "candidate"):
        sel = [(d, e.get(args.key)) for s, d, e in rows if s == tier]
        right = np.array([v for d, v in sel if v is not None and d <= SAME_PLACE_M], float)
        wrong = np.array([v for d, v in sel if v is not None and d > SAME_PLACE_M], float)
        stat = lambda v: "-" if v.size == 0 else f"{v.min():.2f} / {np.median(v):.2f} / {v.max():.2f}"  # noqa: E731
        print(f"| {tier} | {len(sel)} | {right.size} / {wrong.size} | {stat(right)} | {stat(wrong)} |")


if __name__ == "__main__":
    main()
