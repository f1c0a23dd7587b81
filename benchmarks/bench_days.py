"""Three recordings of one world on three days mapped as one site, per pair of recordings.

    python benchmarks/bench_days.py --family first  --seeds 0 --k-across 20,10,4
    python benchmarks/bench_days.py --family second --seeds 0 --k-across 20,10,4

What it is for: the retrieval's budget of matches in the other recordings
(``retrieval_k_across``, ``engine.retrieval.per_other_recording``) only differs from a budget
per recording when a site has three recordings or more, and the day pairs of
``bench_sessions.py`` have two. Days 1 and 2 are ``bench_sessions``' (same cache); day 3 is
the same world once more with ``DAY_THREE`` (other light and exposure, more people, another
start, more of it driven back, another lane and speed), described over day 1's vocabulary.

For each ``--k-across`` value the three .npz files are mapped as one site (``engine.site``)
and each pair of recordings is scored as ``bench_sessions.score_across`` scores a day pair:
shared places (node pairs across the two within 1 m, grouped), found when an automatic loop
joins two of their nodes directly (a place joined only through the third recording is not
counted: a lower bound), with the queue when a candidate does, loops across right / 1-2 m /
false (beyond 2 m). Within each recording: revisits found and false loops as
``bench_sessions.score_within``. Prints a table;
appends nothing to runs.csv (the two-recording figures are ``bench_sessions``').
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_families as bf  # noqa: E402
import bench_sessions as bs  # noqa: E402
from engine.descriptors.base import Descriptors  # noqa: E402
from engine.params import MapParams  # noqa: E402
from engine.retrieval import per_other_recording  # noqa: E402
from engine.synth.sessions import DayTwo  # noqa: E402

# Day 3 against day 1: brighter and bluer where day 2 was darker and warmer, the light turned
# the other way, more walkers, a start further along, half the route driven back, another
# lane and speed. Numbers picked once to differ from day 2, not tuned on any result.
DAY_THREE = DayTwo(exposure=1.25, white_balance=(0.92, 1.0, 1.1), sun_turn=-1.2, people=6,
                   people_seed=2000, start_frac=0.7, back_frac=0.5, lane=0.4, speed=0.75)


def _render_day3(case: bs.PairCase):
    if case.family == "first":
        from bench_methods import case_for
        from engine.synth.sessions import day_pair

        c = case_for(case.route, case.look, case.seed)
        return day_pair(case.route, case.seed, case.look, width=256, height=128, fps=1.0, people=c.people,
                        lighting_drift=c.lighting_drift, noise=c.noise, day2=DAY_THREE)
    from engine.synth2.sessions import day_pair

    return day_pair(case.route, case.seed, width=256, fps=1.0, day2=replace(DAY_THREE, people=10))


def described(case: bs.PairCase, cache: Path) -> list[tuple[Path, Descriptors, object]]:
    """Days 1, 2 (``bench_sessions.described``) and 3, all over day 1's vocabulary."""
    days = bs.described(case, cache, "day1")
    path = bf.cache_path(cache, f"{case.name(3)}_day1")
    if not (path.is_file() and bs._poses_csv(path).is_file()):
        pair = _render_day3(case)   # day 1 again (its vocabulary is not kept in the .npz), and day 3
        model = bs._model()
        d1 = bs._describe(pair.day1.frames, pair.day1.stamps, "day1 again", model)
        if not np.allclose(d1.vectors, days[0][1].vectors, atol=1e-5):
            raise SystemExit(f"{case.name(1)}: day 1 described again differs from the cached one")
        d3 = bs._describe(pair.day2.frames, pair.day2.stamps, path.stem,
                          bs._model(np.array(model.vocabulary, copy=True)))
        d3.save(path)
        bs._save_poses(pair.day2.poses, bs._poses_csv(path))
    return days + [(path, Descriptors.load(path), bs._load_poses(bs._poses_csv(path)))]


def pair_view(view: bs.MapView, s: int, t: int) -> bs.MapView:
    """The part of a site's map on recordings ``s`` and ``t``, relabelled 0 and 1."""
    rows = np.flatnonzero((view.session == s) | (view.session == t))
    new = {int(r): k for k, r in enumerate(rows)}
    loops = [(new[a], new[b], st) for a, b, st in view.loops if a in new and b in new]
    return bs.MapView((view.session[rows] == t).astype(np.int64), view.order[rows], view.stamp[rows], loops,
                      view.how)


PAIRS = ((0, 1), (0, 2), (1, 2))


def run_case(case: bs.PairCase, cache: Path, params: MapParams) -> dict:
    days = described(case, cache)
    site = bs.map_together([p for p, _, _ in days], params)
    poses = [pz for _, _, pz in days]
    across = {(s, t): bs.score_across(pair_view(site, s, t), [poses[s], poses[t]]) for s, t in PAIRS}
    within = [bs.score_within(site, poses, s) for s in range(3)]
    return {"case": case, "across": across, "within": within, "nodes": int(site.session.size)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", choices=("first", "second"), required=True)
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--routes", help="comma-separated routes (default: the family's)")
    ap.add_argument("--k-across", default="20,10,4", help="retrieval_k_across values to compare")
    ap.add_argument("--cache", default="/tmp/panotopo-sessions")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    routes = [r for r in args.routes.split(",") if r] if args.routes else None
    bf.PHOTOMETRIC["value"] = bf.photometric_for(MapParams().method)
    print("| k_across (each other) | route | look | seed | nodes | shared places found 1-2, 1-3, 2-3 | "
          "with queue | across right / 1-2 m / false | within: revisits found (false) | seconds |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    totals = {}
    for ka in [int(x) for x in args.k_across.split(",")]:
        params = MapParams(retrieval_k_across=ka)
        tot = totals.setdefault(ka, {"shared": 0, "found": 0, "with_queue": 0, "right": 0, "between": 0, "false": 0,
                                     "places": 0, "within": 0, "within_false": 0})
        for case in bs.cases(args.family, seeds, routes):
            t0 = time.perf_counter()
            r = run_case(case, Path(args.cache), params)
            x = r["across"]
            for key in ("shared", "found", "with_queue", "right", "between", "false"):
                tot[key] += sum(x[p][key] for p in PAIRS)
            tot["places"] += sum(w["places"] for w in r["within"])
            tot["within"] += sum(w["found"] for w in r["within"])
            tot["within_false"] += sum(w["false"] for w in r["within"])
            found = ", ".join(f"{x[p]['found']}/{x[p]['shared']}" for p in PAIRS)
            queued = ", ".join(f"{x[p]['with_queue']}/{x[p]['shared']}" for p in PAIRS)
            loops = " / ".join(str(sum(x[p][k] for p in PAIRS)) for k in ("right", "between", "false"))
            within = ", ".join(f"{w['found']}/{w['places']}" for w in r["within"])
            print(f"| {ka} ({per_other_recording(ka, 3)}) | {case.route} | {case.look} | {case.seed} | {r['nodes']} "
                  f"| {found} | {queued} | {loops} | {within} "
                  f"({sum(w['false'] for w in r['within'])}) | {time.perf_counter() - t0:.0f} |", flush=True)
    for ka, t in totals.items():
        print(f"k_across {ka}: shared places found {t['found']}/{t['shared']} (with the queue {t['with_queue']}), "
              f"loops across right {t['right']}, "
              f"1-2 m {t['between']}, false {t['false']}; within {t['within']}/{t['places']} "
              f"({t['within_false']} false)")


if __name__ == "__main__":
    main()
