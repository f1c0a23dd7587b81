"""Threshold variants of ``verified`` on described recordings of ONE family (for choosing
thresholds on the first family only; development tool, not part of the tests).

    python benchmarks/sweep_families.py --family first --seeds 0,1,2,3,4 \
        --grid auto_step_share=0.9,1.0,1.1 --grid auto_geometry_z=3,3.5,4

Descriptors come from bench_families.py's cache (run it first). Geometry results are cached
in memory per recording, so each variant costs only the cheap stages.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_families as bf  # noqa: E402
from benchmarks.harness import score_map, sum_rows  # noqa: E402
from engine.params import BY_NAME, MapParams  # noqa: E402
from engine.run import run as run_map  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--family", choices=("first", "second"), default="first")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--cache", default="/tmp/panotopo-families")
    ap.add_argument("--grid", action="append", default=[], metavar="NAME=V1,V2")
    args = ap.parse_args()
    bf.PHOTOMETRIC["value"] = bf.photometric_for("verified")   # the descriptors verified asks for
    seeds = [int(s) for s in args.seeds.split(",")]
    gen = bf.first_family if args.family == "first" else bf.second_family
    recordings = list(gen(seeds, Path(args.cache)))
    names, values = [], []
    for g in args.grid:
        k, vs = g.split("=", 1)
        names.append(k)
        values.append([BY_NAME[k].type(v) for v in vs.split(",")])
    print("| " + " | ".join(names) + " | false auto | events | with candidates | candidates (false) |")
    print("|" + "---|" * (len(names) + 4))
    for combo in itertools.product(*values) if values else [()]:
        p = MapParams(**dict(zip(names, combo)))
        rows = []
        for case, d, poses, fps in recordings:
            rows.append(score_map(run_map(d, p).topomap, poses, case, "verified", bf.EVAL_NN, fps))
        t = sum_rows(rows, "verified")
        worst = sorted((r for r in rows if r.fp), key=lambda r: -r.fp)[:3]
        where = ", ".join(f"{r.route}/{r.look}/s{r.seed}:{r.fp}" for r in worst)
        print(f"| {' | '.join(str(v) for v in combo)} | {t['fp']} | {t['events_found']}/{t['events_total']} | "
              f"{t['events_with_candidates']}/{t['events_total']} | {t['candidates']} ({t['false_candidates']}) |"
              f" {where}", flush=True)


if __name__ == "__main__":
    main()
