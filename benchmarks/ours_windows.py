"""Why the paper's "ours" finds few loops on the first family's crossing and reverse routes.

    python benchmarks/bench_families.py --family first --seeds 0 --methods ours,shift-simple --cache /tmp/pf --no-record
    python benchmarks/ours_windows.py --cache /tmp/pf

Reads the descriptors the first command cached (effnet-vlad, input height 128, plain), maps
them as bench_families does (thresholds calibrated from the recording, neighbor_node_num 5,
window 5, count_th 2) and prints, per route: nodes and their spacing, the same-place pairs
(<= 1 m, more than 5 nodes apart), how many pass loop_sim_th, the best count of a window
holding the other visit's node (what count_th must be below), the median similarity of a
query to the best node of the other visit and to that node's neighbours, and the true and
false loops of ours (count_th 2, 1, 0) and shift-simple.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_methods import case_for
from engine.descriptors.base import Descriptors
from engine.calibrate import paper_thresholds
from engine.nodes import make_nodes
from engine.loops import detect_loops
from engine.params import MapParams

NN, W, CT = 5, 5, 2   # bench_families' EVAL_NN; the paper's window_size and count_th
ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
ap.add_argument("--cache", default="/tmp/pf", help="bench_families' --cache")
ap.add_argument("--fps", type=float, default=1.0,
                help="frames per second: other than 1, the routes are rendered and described here "
                     "(cached as <name>_fps<F>_h128.npz): denser frames, denser nodes")
ap.add_argument("--routes", default="crossing,reverse")
ARGS = ap.parse_args()
CACHE = Path(ARGS.cache)


def descriptors(route: str, look: str, name: str):
    if ARGS.fps == 1.0:
        path = CACHE / f"{name}_h128.npz"
        return (Descriptors.load(path) if path.is_file() else None), case_for(route, look, 0).poses()
    from engine.pipeline import DescribeSettings, describe_frames
    from engine.frames import Frame
    from engine.synth import make_recording

    c = case_for(route, look, 0)
    rec = make_recording(route, look, 0, width=256, height=128, fps=ARGS.fps, people=c.people,
                         lighting_drift=c.lighting_drift, noise=c.noise)
    path = CACHE / f"{name}_fps{ARGS.fps:g}_h128.npz"
    if path.is_file():
        return Descriptors.load(path), rec.poses
    items = (Frame(k, float(t), rgb) for k, (t, rgb) in enumerate(zip(rec.stamps, rec.frames)))
    d = describe_frames(items, len(rec.stamps), DescribeSettings(interval=0.0, options={"input_height": 128}),
                        source=name)
    d.save(path)
    return d, rec.poses


for route in ARGS.routes.split(","):
    for look in ("indoor", "outdoor"):
        name = f"first_{route}_{look}_s0"
        d, poses = descriptors(route, look, name)
        if d is None:
            print(name, "not cached"); continue
        th = paper_thresholds(d.vectors, NN)
        rows = make_nodes(d.vectors, th["node_sim_th"])
        v = d.vectors[rows]
        x, y = poses.at(d.stamps[rows])
        m = len(rows)
        S = v @ v.T
        step = np.hypot(np.diff(x), np.diff(y))
        D = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
        I, J = np.nonzero((D <= 1.0) & (np.arange(m)[None, :] - np.arange(m)[:, None] > NN))
        hit = S >= np.float32(th["loop_sim_th"])
        # For query i, the best count of a window that holds j (and is not skipped).
        best = []
        for i, j in zip(I, J):
            c = 0
            for s in range(max(0, j - W + 1), min(j, m - W) + 1):
                if s <= i + NN and s + W - 1 >= i - NN:
                    continue
                c = max(c, int(hit[i, s:s + W].sum()))
            best.append(c)
        best = np.array(best, int)
        # Nodes of the other visit within 1 m of node i (in one window's reach or not).
        near = np.array([int(((D[i] <= 1.0) & (np.abs(np.arange(m) - j) < W)).sum()) for i, j in zip(I, J)])
        # Along the other visit: similarity of query i to the best node j of it and to j +- 1, +- 2.
        prof = {k: [] for k in range(-2, 3)}
        for i in np.unique(I):
            js = J[I == i]
            j = int(js[np.argmax(S[i, js])])
            for k in prof:
                if 0 <= j + k < m:
                    prof[k].append(float(S[i, j + k]))
        profile = " ".join(f"{k:+d}:{np.median(vals):.3f}" for k, vals in prof.items() if vals)
        res = {}
        for method, extra in (("ours", {}), ("shift-simple", {}), ("ours count_th=1", {"count_th": 1}),
                              ("ours count_th=0", {"count_th": 0})):
            meth = method.split()[0]
            p = MapParams(method=meth, node_sim_th=th["node_sim_th"], loop_sim_th=th["loop_sim_th"],
                          window_size=W, count_th=extra.get("count_th", CT), neighbor_node_num=NN)
            loops = detect_loops(v, p)
            tp = sum(1 for l in loops if D[l.a, l.b] <= 1.0 and l.b - l.a > NN)
            res[method] = (tp, len(loops) - tp)
        print(f"{name}: frames {len(d)} nodes {m} node_sim_th {th['node_sim_th']:.3f} loop_sim_th {th['loop_sim_th']:.3f} "
              f"median step {np.median(step):.2f} m; same-place pairs {len(I)}, with sim>=th {int(hit[I, J].sum())}; "
              f"best window count for (i->j) histogram {np.bincount(best, minlength=W + 1).tolist()}; "
              f"other-visit nodes within 1 m in j's window, histogram {np.bincount(near, minlength=W + 1).tolist()}; "
              f"TP/FP {res}; median sim of query to best other-visit node j and its neighbours {profile}")
