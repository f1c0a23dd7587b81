"""How many revisits stage 7's measured distance can reach at all, and how exact the measure is
near its threshold (development tool).

    python benchmarks/place_ceiling.py --family second --seeds 55,56,57 --cache C
    python benchmarks/place_ceiling.py --family first --seeds 0,1 --sites --cache S

Stage 7 takes two views as one place when they measure at most ``auto_distance_steps`` node
steps apart; the evaluation counts two nodes as one place when they are at most 1 m apart.
The two meet only through the node step's length in metres, which the method does not know.

1. **Ceiling.** Each revisit event's closest same-place pair in node steps (its metres over the
   longer of its two ends' mean step lengths). An event with no pair within the threshold
   cannot be closed by a measured distance however exact the measure and whatever else is
   right: the share of events within each threshold is the most the rule can reach.
2. **The measure near the threshold.** For every loop the map exports (automatic loops and
   candidates) whose distance was measured: measured steps over true steps, by band of true
   steps, and the loops more than 1 m apart that measure within each threshold.

Reads the recordings of ``bench_families.py``'s cache (``--methods verified`` renders them);
``--sites``: the day pairs of ``bench_sessions.py``'s cache mapped as one site each, the
events then being the places the two days share (``bench_sessions.score_across``) and the
loops every loop of the site.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_families as bf  # noqa: E402
from engine.evaluate import _events, _positive_pairs, node_positions  # noqa: E402
from engine.params import MapParams  # noqa: E402
from engine.run import run as run_map  # noqa: E402

SAME_PLACE_M = 1.0
THRESHOLDS = (1.0, 1.1, 1.15, 1.2, 1.25, 1.3)
BANDS = ((0.0, 0.9), (0.9, 1.1), (1.1, 1.3), (1.3, 1.6), (1.6, 3.0))


def step_lengths(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Each node's mean distance to its previous and next node along the path (metres)."""
    steps = np.hypot(np.diff(x), np.diff(y))
    before = np.concatenate([[np.nan], steps])
    after = np.concatenate([steps, [np.nan]])
    return np.nanmean(np.stack([before, after]), axis=0)


def recording_rows(descs, poses, params: MapParams):
    """(closest pair in steps per event, [(true steps, measured steps, metres)] per measured loop)."""
    topomap = run_map(descs, params).topomap
    x, y = (np.asarray(v, float) for v in node_positions(topomap, poses))
    local = step_lengths(x, y)
    pi, pj = _positive_pairs(x, y, SAME_PLACE_M, params.neighbor_node_num)
    closest = []
    if pi.size:
        in_steps = np.hypot(x[pi] - x[pj], y[pi] - y[pj]) / np.maximum(local[pi], local[pj])
        labels = _events(pi, pj, x.size)
        closest = [float(in_steps[labels == e].min()) for e in np.unique(labels)]
    measured = []
    nodes = topomap.graph.nodes
    for u, w, attrs in topomap.loops(("auto", "candidate")):
        steps = attrs.get("distance_steps")
        if steps is None or not np.isfinite(steps):
            continue
        a, b = int(nodes[u]["index"]), int(nodes[w]["index"])
        metres = float(np.hypot(x[a] - x[b], y[a] - y[b]))
        measured.append((metres / max(local[a], local[b]), float(steps), metres))
    return closest, measured


def site_rows(case, cache: Path, params: MapParams):
    """``recording_rows`` for a day pair of ``bench_sessions`` mapped as one site: the places the
    two days share, and every measured loop of the site (within and across the days)."""
    import bench_sessions as bs

    days = bs.described(case, cache)
    view = bs.map_together([p for p, _, _ in days], params)
    x, y = bs.positions(view, [pz for _, _, pz in days])
    local = np.full(x.size, np.nan)
    for s in (0, 1):
        rows = np.flatnonzero(view.session == s)
        local[rows] = step_lengths(x[rows], y[rows])
    ra, rb, labels = bs.shared_places(view, x, y)
    in_steps = np.hypot(x[ra] - x[rb], y[ra] - y[rb]) / np.maximum(local[ra], local[rb])
    closest = [float(in_steps[labels == e].min()) for e in np.unique(labels)]
    measured = []
    for a, b, steps in view.measured:
        d = float(np.hypot(x[a] - x[b], y[a] - y[b]))
        measured.append((d / max(local[a], local[b]), steps, d))
    return closest, measured


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", choices=("first", "second"), default="first")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--cache", help="descriptor cache (default: the benchmark's own)")
    ap.add_argument("--sites", action="store_true", help="the day pairs of bench_sessions.py, each one site")
    args = ap.parse_args()
    bf.PHOTOMETRIC["value"] = bf.photometric_for("verified")   # the descriptors verified asks for
    seeds = [int(s) for s in args.seeds.split(",")]
    by_route: dict[str, list[float]] = {}
    measured: list[tuple[float, float, float]] = []
    if args.sites:
        import bench_sessions as bs

        cache = Path(args.cache or "/tmp/panotopo-sessions")
        params = MapParams(method="verified")
        results = ((c.route, site_rows(c, cache, params)) for c in bs.cases(args.family, seeds))
    else:
        gen = bf.first_family if args.family == "first" else bf.second_family
        params = MapParams(method="verified", neighbor_node_num=5)
        results = ((case.route, recording_rows(descs, poses, params))
                   for case, descs, poses, _fps in gen(seeds, Path(args.cache or "/tmp/panotopo-families")))
    for route, (closest, rows) in results:
        by_route.setdefault(route, []).extend(closest)
        measured.extend(rows)

    what = "places two days share" if args.sites else "revisit events"
    print(f"{args.family} family, seeds {args.seeds}: {what} whose closest same-place pair is "
          f"within a threshold (node steps; the most a measured-distance rule at that threshold can close)\n")
    print("| route | events | " + " | ".join(f"<= {t:g}" for t in THRESHOLDS) + " |")
    print("|---|---:|" + "---:|" * len(THRESHOLDS))
    for route, values in sorted(by_route.items()) + [("all", sum(by_route.values(), []))]:
        v = np.asarray(values)
        if v.size:
            print(f"| {route} | {v.size} | " + " | ".join(f"{np.mean(v <= t):.1%}" for t in THRESHOLDS) + " |")

    if not measured:
        return
    true_steps, steps, metres = (np.asarray(c) for c in zip(*measured))
    print(f"\nMeasured over true node steps, exported loops whose distance was measured ({true_steps.size}):\n")
    print("| true steps | loops | median | 5th-95th percentile |")
    print("|---|---:|---:|---|")
    for lo, hi in BANDS:
        r = (steps / true_steps)[(true_steps >= lo) & (true_steps < hi)]
        if r.size:
            print(f"| {lo:g}-{hi:g} | {r.size} | {np.median(r):.3f} | "
                  f"{np.percentile(r, 5):.3f}-{np.percentile(r, 95):.3f} |")
    print(f"\nExported loops more than {SAME_PLACE_M:g} m apart measured within each threshold "
          "(any tier; how far apart, up to 1.5 m):\n")
    for t in THRESHOLDS:
        wrong = np.sort(metres[(metres > SAME_PLACE_M) & (steps <= t)])
        near = ", ".join(f"{m:.2f}" for m in wrong[wrong <= 1.5])
        print(f"- <= {t:g}: {wrong.size} ({near or 'none within 1.5 m'})")


if __name__ == "__main__":
    main()
