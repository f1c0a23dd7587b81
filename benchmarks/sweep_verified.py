"""Threshold variants of ``verified`` on benchmark recordings, described once.

    python benchmarks/sweep_verified.py --seeds 100,101 --cache /tmp/ptq [--set run_z=3.8,seq_z=3.5 ...] [-v]

Every --set (comma-separated name=value of ``VerifiedThresholds``) is one variant; without
--set, the defaults. For each variant: false loops and places found over all recordings
(with -v, the recordings that had a false loop or missed a place, and the false pairs).
This is for choosing thresholds on seeds seen already; report on seeds never used with
``bench_methods.py --mode heldout``. Recordings are the heldout benchmark's (every route
type, both looks, the disturbances of seed % 5), described into --cache if not there.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from bench_methods import LOOKS, ROUTE_TYPES, case_for
from engine.benchmark import describe_case
from engine.calibrate import node_threshold
from engine.evaluate import evaluate
from engine.graph import TopoMap
from engine.loops_verified import DEFAULT_THRESHOLDS, VerifiedThresholds, verified_loops
from engine.nodes import make_nodes
from engine.params import MapParams

EVAL_NN = 5   # temporal neighbours never counted, as in bench_methods


def parse_variant(text: str) -> VerifiedThresholds:
    names = set(VerifiedThresholds.__dataclass_fields__)
    values = {}
    for item in filter(None, text.split(",")):
        name, _, value = item.partition("=")
        if name not in names:
            raise SystemExit(f"error: unknown threshold '{name}' (known: {', '.join(sorted(names))})")
        values[name] = float(value)
    return replace(DEFAULT_THRESHOLDS, **values)


def load_recordings(seeds: list[int], cache: Path) -> list[tuple]:
    """(name, descriptors, node rows, poses) of every recording, nodes as ``build_map`` makes them."""
    out = []
    for seed in seeds:
        for route in ROUTE_TYPES:
            for look in LOOKS:
                case = case_for(route, look, seed)
                d = describe_case(case, (True,), cache_dir=cache)
                descs = d.by_shift[True]
                out.append((case.name, descs, make_nodes(descs.vectors, node_threshold(descs.vectors)), d.poses))
    return out


def run_variant(recordings: list[tuple], th: VerifiedThresholds, verbose: bool) -> tuple[int, int, int]:
    params = MapParams(neighbor_node_num=EVAL_NN)
    fp = found = total = 0
    for name, descs, rows, poses in recordings:
        loops = verified_loops(descs.vectors[rows], params, descs.columns[rows], descs.shifts[rows],
                               int(descs.meta.get("frame_width", 0)), th, descs.colours[rows])
        ev = evaluate(TopoMap.build(descs, rows, loops, params), poses, neighbor_node_num=EVAL_NN)
        fp, found, total = fp + ev.fp, found + ev.events_found, total + ev.events_total
        if verbose and (ev.fp or ev.events_found < ev.events_total):
            print(f"  {name}: false loops {ev.fp_pairs}, places {ev.events_found}/{ev.events_total}")
    return fp, found, total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", required=True, help="comma-separated seeds")
    ap.add_argument("--cache", default="/tmp/ptb", help="descriptor cache (as bench_methods --cache)")
    ap.add_argument("--set", action="append", default=[], help="one variant: name=value,name=value")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    recordings = load_recordings([int(s) for s in args.seeds.split(",")], Path(args.cache))
    for text in args.set or [""]:
        fp, found, total = run_variant(recordings, parse_variant(text), args.verbose)
        print(f"{text or 'defaults'}: false loops {fp}, places {found}/{total}")


if __name__ == "__main__":
    main()
