"""Speed and outcome of stage 7's pose graph with metric factors (engine/metric.py) on a
synthetic long recording: laps of a 120 m square, 1.2 m per node step, image steps with 1 degree
of turn noise, a true loop every 25 nodes to the lap before, one wrong loop per 20 true ones
(150-250 nodes apart); GPS with 2 m of noise per fix, odometry whose heading drifts
0.005 rad per step. Prints seconds, the share of true and wrong loops kept and the largest
distance of a node from the truth (metres; the image-only graph is in node steps).

    python benchmarks/bench_metric_graph.py --nodes 20000 --cases image,gps,odometry
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from engine.loops.pairs import Steps
from engine.loops.pose_graph import Loops, solve
from engine.metric import Metric
from engine.params import MapParams

LAP = 400          # nodes per lap: 4 sides of 100 steps
STEP_M = 1.2


def scene(nodes: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    n, m = nodes - 1, nodes
    yaw = np.zeros(n)
    yaw[99::100] = 90.0
    heading = np.concatenate([[0.0], np.cumsum(np.radians(yaw))])
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(STEP_M * np.stack([np.cos(heading[:-1]), np.sin(heading[:-1])], 1), 0)])
    steps = Steps(yaw=yaw + rng.normal(0, 1, n), motion=rng.normal(0, 2, n), still=np.zeros(n, bool),
                  ambiguous=np.zeros(n, bool))
    gps = xy + rng.normal(0, 2, xy.shape)
    drifted = heading + np.cumsum(rng.normal(0, 0.005, m))
    odo_xy = np.concatenate([[[0.0, 0.0]], np.cumsum(STEP_M * np.stack([np.cos(drifted[:-1]), np.sin(drifted[:-1])], 1), 0)])
    odometry = np.column_stack([odo_xy, drifted])
    a = np.arange(0, m - LAP, 25)
    fa = rng.integers(0, m - 300, a.size // 20)
    fb = fa + rng.integers(150, 250, fa.size)
    loops = Loops(np.concatenate([a, fa]), np.concatenate([a + LAP, fb]), np.full(a.size + fa.size, np.nan))
    return m, steps, loops, a.size, xy, {"image": None, "gps": Metric(gps=gps), "odometry": Metric(odometry=odometry),
                                         "odometry+gps": Metric(odometry=odometry, gps=gps)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=20000)
    ap.add_argument("--cases", default="image,gps,odometry")
    args = ap.parse_args()
    m, steps, loops, true_count, xy, metrics = scene(args.nodes)
    for case in args.cases.split(","):
        t0 = time.perf_counter()
        sol = solve(m, steps, loops, MapParams(), metric=metrics[case])
        seconds = time.perf_counter() - t0
        off = np.linalg.norm(sol.poses[:, :2] - xy, axis=1).max() if metrics[case] is not None else float("nan")
        print(f"{case:13s} {args.nodes} nodes {seconds:7.1f} s  true kept {sol.kept[:true_count].mean():.3f}  "
              f"wrong kept {sol.kept[true_count:].mean():.3f}  m per step {sol.unit:.3f}  largest miss {off:.1f} m",
              flush=True)


if __name__ == "__main__":
    main()
