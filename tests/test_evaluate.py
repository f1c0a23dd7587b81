import json

import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.evaluate import evaluate
from engine.graph import TopoMap
from engine.loops import LoopCandidate
from engine.params import MapParams
from engine.poses import Poses

# Hand-made route, 13 nodes (index: x, y in metres): out along y = 0, a turn, back
# the same way, a detour, and a return next to node 4.
POSITIONS = np.array([
    (0.0, 0.0),   # 0
    (2.0, 0.0),   # 1
    (4.0, 0.0),   # 2
    (6.0, 0.0),   # 3
    (6.0, 2.0),   # 4
    (5.5, 0.8),   # 5  0.94 m from node 3, but only 2 nodes later
    (4.0, 0.5),   # 6  0.5 m from node 2
    (2.0, 0.3),   # 7  0.3 m from node 1
    (0.0, 0.4),   # 8  0.4 m from node 0
    (0.0, 0.9),   # 9  0.9 m from node 0 (0.5 m from node 8, but that is a path arc)
    (10.0, 5.0),  # 10
    (8.0, 4.0),   # 11
    (6.2, 2.1),   # 12 0.22 m from node 4
])


def hand_map(nn: int = 2) -> TopoMap:
    m = len(POSITIONS)
    rng = np.random.default_rng(0)
    v = rng.normal(size=(m, 8)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    descs = Descriptors(stamps=np.arange(m, dtype=np.float64) * 2.0, frames=np.arange(m) * 60,
                        shifts=np.zeros(m, np.int64), vectors=v, meta={"descriptor": "t"})
    loops = [LoopCandidate(a, b, 0.6, 3) for a, b in
             [(2, 6), (0, 8), (3, 5), (1, 10), (4, 12), (6, 11)]]
    params = MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.5, neighbor_node_num=nn)
    tm = TopoMap.build(descs, np.arange(m), loops, params)
    tm.set_status("n0", "n8", "confirmed")
    tm.set_status("n4", "n12", "rejected")
    tm.set_status("n6", "n11", "rejected")
    return tm


def hand_poses() -> Poses:
    # Poses sampled at the node stamps (2 s apart) plus midpoints, so at() interpolates.
    t = np.arange(len(POSITIONS)) * 2.0
    mid_t = t[:-1] + 1.0
    mid = (POSITIONS[:-1] + POSITIONS[1:]) / 2
    order = np.argsort(np.concatenate([t, mid_t]))
    allp = np.concatenate([POSITIONS, mid])[order]
    return Poses(t=np.concatenate([t, mid_t])[order], x=allp[:, 0], y=allp[:, 1])


def test_hand_counted_map():
    ev = evaluate(hand_map(), hand_poses(), dist_th=1.0)
    # 13 nodes: (12 * 11) / 2 = 66 pairs once path arcs (j - i == 1) are left out.
    # Same place (<= 1 m), j - i > neighbor_node_num = 2: (2,6) (1,7) (0,8) (0,9) (4,12).
    # (3,5) is 0.94 m but only 2 apart: a temporal neighbour, never a positive.
    # Detected (not rejected): (2,6) TP, (0,8) TP (confirmed), (3,5) FP (neighbours),
    # (1,10) FP (far apart). Rejected: (4,12) -> still FN, (6,11) -> TN.
    # FN = positives not detected: (1,7) (0,9) (4,12). TN = 66 - 2 - 2 - 3 = 59.
    assert (ev.tp, ev.fp, ev.fn, ev.tn) == (2, 2, 3, 59)
    assert ev.tp_pairs == [(0, 8), (2, 6)]
    assert sorted(ev.fp_pairs) == [(1, 10), (3, 5)]
    assert sorted(ev.fn_pairs) == [(0, 9), (1, 7), (4, 12)]
    assert ev.precision == pytest.approx(2 / 4)
    assert ev.recall == pytest.approx(2 / 5)
    assert ev.accuracy == pytest.approx(61 / 66)
    assert ev.f1 == pytest.approx(4 / 9)
    # Events: (2,6) (1,7) (0,8) (0,9) touch diagonally (the drive back), one event,
    # found through its TPs; (4,12) is a second event, its loop was rejected: missed.
    assert (ev.events_found, ev.events_total) == (1, 2)
    # Per event, hand-counted: closest pair (1,7) 0.3 m and (4,12) 0.22 m; the most nodes
    # between two visits: (0,9) 9 nodes for the drive back, (4,12) 8.
    assert ev.event_closest == pytest.approx([0.3, np.hypot(0.2, 0.1)])
    assert ev.event_span == [9, 8] and ev.event_found == [True, False]
    assert ev.event_coverage == pytest.approx(0.5)
    assert ev.loop_truth == {("n0", "n8"): "TP", ("n1", "n10"): "FP", ("n2", "n6"): "TP",
                             ("n3", "n5"): "FP", ("n4", "n12"): "FN", ("n6", "n11"): "TN"}
    assert ev.neighbor_node_num == 2  # taken from the map's parameters
    json.dumps(ev.as_dict())


def test_other_neighbourhood_and_distance():
    tm = hand_map()
    # neighbor_node_num 1: (3,5) is now a positive, and detected -> TP; it touches
    # (2,6) diagonally, so it joins the first event.
    ev = evaluate(tm, hand_poses(), dist_th=1.0, neighbor_node_num=1)
    assert (ev.tp, ev.fp, ev.fn, ev.tn) == (3, 1, 3, 59)
    assert (ev.events_found, ev.events_total) == (1, 2)
    # 0.35 m: positives only (1,7) 0.3 m and (4,12) 0.22 m, neither detected; the four
    # detected loops are all FP.
    ev = evaluate(tm, hand_poses(), dist_th=0.35)
    assert (ev.tp, ev.fp, ev.fn, ev.tn) == (0, 4, 2, 60)
    assert ev.precision == 0.0 and ev.recall == 0.0 and ev.f1 == 0.0
    assert (ev.events_found, ev.events_total) == (0, 2)



def test_a_pair_exactly_the_distance_threshold_apart_is_the_same_place():
    """0.6 m along and 0.8 m across is 1.0 m: its squared distance computes as 1 + 2e-15,
    which must not turn a true loop into a false one."""
    tm = hand_map()
    pos = POSITIONS.copy()
    pos[10] = pos[1] + (0.6000000000000014, -0.8)   # the offset route's stagger, as computed
    assert (pos[10] - pos[1]) @ (pos[10] - pos[1]) > 1.0
    t = np.arange(len(pos)) * 2.0
    ev = evaluate(tm, Poses(t=t, x=pos[:, 0], y=pos[:, 1]), dist_th=1.0)
    assert (1, 10) in ev.tp_pairs
    pos[10] = pos[1] + (0.0, 1.001)                   # a millimetre further is not
    ev = evaluate(tm, Poses(t=t, x=pos[:, 0], y=pos[:, 1]), dist_th=1.0)
    assert (1, 10) in ev.fp_pairs

def test_positions_from_node_attributes():
    tm = hand_map()
    with pytest.raises(InputError, match="no ground-truth poses"):
        evaluate(tm)
    tm.set_positions(POSITIONS[:, 0], POSITIONS[:, 1])
    ev = evaluate(tm)
    assert (ev.tp, ev.fp, ev.fn, ev.tn) == (2, 2, 3, 59)


def brute_events(positives: set, found: set) -> tuple[int, int]:
    """Union-find over positive pairs touching in the 8-neighbourhood of the (i, j) grid."""
    parent = {p: p for p in positives}

    def root(p):
        while parent[p] != p:
            p = parent[p]
        return p

    for i, j in positives:
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                q = (i + di, j + dj)
                if q in parent:
                    parent[root(q)] = root((i, j))
    roots = {root(p) for p in positives}
    return len({root(p) for p in found}), len(roots)


def brute_force(x, y, detected, th, nn):
    m = len(x)
    tp = fp = fn = tn = 0
    for i in range(m):
        for j in range(i + 2, m):
            same = np.hypot(x[i] - x[j], y[i] - y[j]) <= th
            positive = same and j - i > nn
            det = (i, j) in detected
            if det and positive:
                tp += 1
            elif det:
                fp += 1
            elif positive:
                fn += 1
            else:
                tn += 1
    return tp, fp, fn, tn


@pytest.mark.parametrize("seed", range(4))
def test_matches_brute_force_on_random_maps(seed, monkeypatch):
    import engine.evaluate as evmod

    monkeypatch.setattr(evmod, "_BLOCK_ELEMENTS", 50)  # force many row blocks
    rng = np.random.default_rng(seed)
    m = 60
    xy = np.cumsum(rng.normal(size=(m, 2)), axis=0) * 0.4  # a wandering robot
    v = rng.normal(size=(m, 4)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    descs = Descriptors(np.arange(m, dtype=float), np.arange(m), np.zeros(m, np.int64), v, {})
    pairs = {(int(a), int(b)) for a, b in rng.integers(0, m, size=(80, 2)) if b - a >= 2}
    loops = [LoopCandidate(a, b, 0.5, 0) for a, b in sorted(pairs)]
    tm = TopoMap.build(descs, np.arange(m), loops, MapParams(loop_sim_th=0.5, node_sim_th=0.8))
    tm.set_positions(xy[:, 0], xy[:, 1])
    ev = evaluate(tm, dist_th=1.0, neighbor_node_num=3)
    assert (ev.tp, ev.fp, ev.fn, ev.tn) == brute_force(xy[:, 0], xy[:, 1], pairs, 1.0, 3)
    positives = {(i, j) for i in range(m) for j in range(i + 4, m)
                 if np.hypot(*(xy[i] - xy[j])) <= 1.0}
    assert positives, "the wandering robot comes back somewhere"
    assert (ev.events_found, ev.events_total) == brute_events(positives, set(ev.tp_pairs))


def square_route_map(method: str = "ours"):
    """A robot drives a 20 m square one and a half times; descriptors depend on position."""
    rng = np.random.default_rng(1)
    s = np.arange(0, 120, 1.0)  # one node per metre
    side = (s % 80) // 20
    f = (s % 20)
    x = np.select([side == 0, side == 1, side == 2, side == 3], [f, 20 + 0 * f, 20 - f, 0 * f])
    y = np.select([side == 0, side == 1, side == 2, side == 3], [0 * f, f, 20 + 0 * f, 20 - f])
    x = x + rng.normal(scale=0.2, size=s.size)
    y = y + rng.normal(scale=0.2, size=s.size)
    w = rng.normal(scale=0.35, size=(2, 64))
    phase = rng.uniform(0, 2 * np.pi, 64)
    v = np.cos(np.c_[x, y] @ w + phase) + 0.1 * rng.normal(size=(s.size, 64))
    v = (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)
    descs = Descriptors(s.copy(), np.arange(s.size) * 30, np.zeros(s.size, np.int64), v,
                        {"descriptor": "fourier"})
    params = MapParams(method=method, node_sim_th=0.8, loop_sim_th=0.75, window_size=5,
                       count_th=2, neighbor_node_num=5)
    from engine.loops import detect_loops

    loops = detect_loops(v, params)
    tm = TopoMap.build(descs, np.arange(s.size), loops, params)
    return tm, Poses(t=s, x=x, y=y)


@pytest.mark.parametrize("with_poses", [True, False])
def test_plot_map_writes_a_png(tmp_path, with_poses):
    from engine.plots import plot_map

    tm, poses = square_route_map("simple")
    ev = evaluate(tm, poses)
    assert ev.tp > 0 and ev.fp > 0  # the picture has both colours to show
    path = tmp_path / "map.png"
    plot_map(tm, poses if with_poses else None, ev if with_poses else None, path)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    assert img.shape[0] == 600 and img.shape[1] == 1300
    if with_poses:
        # Green (TP) and red (FP) loop lines are drawn somewhere.
        rgb = img[..., :3]
        green = (rgb[..., 1] > 0.45) & (rgb[..., 0] < 0.35) & (rgb[..., 2] < 0.35)
        red = (rgb[..., 0] > 0.7) & (rgb[..., 1] < 0.3) & (rgb[..., 2] < 0.3)
        assert green.sum() > 50 and red.sum() > 50


# ----- several recordings (a site map): nodes carry ``session``, each on its own clock --------
# A drives out along y = 0 (x = 0, 2, ..., 10), B drives back along y = 0.3 (x = 10, 8, ..., 0);
# both recordings start at t = 0 and frame 0.
SITE_A = np.array([(2.0 * k, 0.0) for k in range(6)])
SITE_B = np.array([(10.0 - 2.0 * k, 0.3) for k in range(6)])


def site_map() -> TopoMap:
    m = 12
    rng = np.random.default_rng(1)
    v = rng.normal(size=(m, 8)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    descs = Descriptors(stamps=np.tile(np.arange(6) * 2.0, 2), frames=np.tile(np.arange(6) * 60, 2),
                        shifts=np.zeros(m, np.int64), vectors=v, meta={"descriptor": "t"})
    loops = [LoopCandidate(a, b, 0.6, 3) for a, b in
             [(0, 11), (5, 6), (2, 9), (1, 7), (0, 3)]]
    params = MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.5, neighbor_node_num=1)
    return TopoMap.build(descs, np.arange(m), loops, params, sessions=["A"] * 6 + ["B"] * 6)


def site_poses() -> dict:
    t = np.arange(6) * 2.0
    return {"A": Poses(t=t, x=SITE_A[:, 0], y=SITE_A[:, 1]), "B": Poses(t=t, x=SITE_B[:, 0], y=SITE_B[:, 1])}


def test_a_site_counts_pairs_across_recordings_apart_and_the_boundary_is_no_path_arc():
    tm = site_map()
    g = tm.graph
    assert not g.has_edge("n5", "n6") or g.edges["n5", "n6"]["kind"] == "loop"   # no path between recordings
    ev = evaluate(tm, site_poses(), dist_th=0.5)
    # across: (0, 11), (5, 6) and (2, 9) join one place, (1, 7) two places 6 m apart
    assert (ev.cross_tp, ev.cross_fp) == (3, 1)
    assert ev.fp - ev.cross_fp == 1                        # (0, 3) within A: two places
    assert ev.tp + ev.fp + ev.tn + ev.fn == 12 * 11 // 2 - 10   # every pair less the 10 path arcs
    # every place of A is driven again in B: six places across, three found
    assert ev.cross_events_total == ev.events_total and ev.cross_fn == ev.fn
    assert 1 <= ev.cross_events_found <= ev.cross_events_total
    assert ev.sessions == 2


def test_a_site_needs_one_set_of_poses_per_recording():
    tm = site_map()
    with pytest.raises(InputError, match="one set of poses per recording"):
        evaluate(tm, site_poses()["A"])
    with pytest.raises(InputError, match="recording B"):
        evaluate(tm, {"A": site_poses()["A"]})


def test_site_decisions_are_keyed_by_session_and_frame():
    tm = site_map()
    tm.set_status("n2", "n9", "rejected")   # frames 120 (A) and 180 (B)
    tm.set_label("n8", "door")              # frame 120 of B, the same frame number as n2 of A
    dec = tm.decisions()
    assert dec["loops"] == [{"frames": [120, 180], "status": "rejected", "sessions": ["A", "B"]}]
    assert dec["labels"] == [{"frame": 120, "label": "door", "session": "B"}]
    again = site_map()
    again.apply_decisions({**dec, "labels": dec["labels"] + [{"frame": 0, "label": "x", "session": "C"}]})
    assert again.graph.edges["n2", "n9"]["status"] == "rejected"
    assert again.graph.nodes["n8"]["label"] == "door" and again.graph.nodes["n2"]["label"] == ""
    assert again.unapplied["labels"] == [{"frame": 0, "label": "x", "session": "C"}]   # not in this map: kept
