"""The path layout used without ground truth: a straight walk never crosses itself."""

from __future__ import annotations

import numpy as np

from gui.model.layout import EMBED_MAX_NODES, decided_layout, path_layout
from tests.gui_maps import make_doc


def _crossings(x: np.ndarray, y: np.ndarray) -> int:
    """Pairs of non-adjacent path segments that properly intersect."""
    p = np.stack([x, y], axis=1)
    a, b = p[:-1], p[1:]
    i, j = np.triu_indices(len(a), k=2)

    def orient(p1, p2, q):
        return np.sign((p2[:, 0] - p1[:, 0]) * (q[:, 1] - p1[:, 1]) - (p2[:, 1] - p1[:, 1]) * (q[:, 0] - p1[:, 0]))

    o1, o2 = orient(a[i], b[i], a[j]), orient(a[i], b[i], b[j])
    o3, o4 = orient(a[j], b[j], a[i]), orient(a[j], b[j], b[i])
    return int(np.count_nonzero((o1 * o2 < 0) & (o3 * o4 < 0)))


def test_a_straight_walk_is_drawn_without_crossing_itself():
    for n in (12, 80, 300, 600):
        doc = make_doc(None, (), n=n)
        x, y = path_layout(doc.topomap)
        assert _crossings(x, y) == 0, f"a walk of {n} nodes with no loops crosses itself"
        steps = np.hypot(np.diff(x), np.diff(y))
        assert steps.min() > 0.5, "consecutive nodes are drawn apart"
        if n <= EMBED_MAX_NODES:  # not a spiral: the walk goes somewhere (ends far apart for its length)
            assert np.hypot(x[-1] - x[0], y[-1] - y[0]) > 0.5 * steps.sum()


def test_a_long_walk_is_laid_out_compactly_without_crossing():
    n = EMBED_MAX_NODES + 100
    doc = make_doc(None, (), n=n)
    x, y = path_layout(doc.topomap)
    assert _crossings(x, y) == 0
    width, height = np.ptp(x), np.ptp(y)
    assert 0.5 < width / height < 8, "a long walk fills a graph view instead of being a thin line"


def test_a_loop_pulls_its_two_places_together():
    n = 40
    doc = make_doc(None, [(0, n - 1, "auto")], n=n)
    x, y = path_layout(doc.topomap)
    gap = np.hypot(x[0] - x[-1], y[0] - y[-1])
    assert gap < 0.25 * (n - 1), "the revisit is drawn near the place it revisits"
    assert _crossings(x, y) == 0, "a single loop is drawn as a loop, not a tangle"


def test_a_rejected_loop_does_not_fold_the_path():
    n = 40
    doc = make_doc(None, [(0, n - 1, "rejected")], n=n)
    x, y = path_layout(doc.topomap)
    assert np.hypot(x[0] - x[-1], y[0] - y[-1]) > 0.5 * (n - 1)


def _candidates(n: int, count: int, seed: int = 3) -> list:
    rng = np.random.default_rng(seed)
    pairs = set()
    while len(pairs) < count:
        a, b = sorted(int(v) for v in rng.integers(0, n, size=2))
        if b - a > 5:
            pairs.add((a, b))
    return [(a, b, "candidate") for a, b in sorted(pairs)]


def test_undecided_candidates_do_not_tie_the_path_into_a_knot():
    """Issue 43, defect 2: with 35 candidates the path was a knot; rejecting them all left it."""
    n = 120
    loops = _candidates(n, 35)
    doc = make_doc(None, loops, n=n)
    xy = decided_layout(doc.topomap)
    assert _crossings(xy[:, 0], xy[:, 1]) == 0, "candidates nobody accepted fold the path"
    for a, b, _ in loops:
        doc.topomap.graph.edges[f"n{a}", f"n{b}"]["status"] = "rejected"
    xy = decided_layout(doc.topomap)
    assert _crossings(xy[:, 0], xy[:, 1]) == 0
    assert np.hypot(*(xy[-1] - xy[0])) > 0.5 * (n - 1), "all rejected: the walk is drawn straight"


def test_a_confirmed_loop_folds_the_decided_map():
    n = 40
    doc = make_doc(None, [(0, n - 1, "candidate")], n=n)
    before = decided_layout(doc.topomap)
    doc.topomap.graph.edges["n0", f"n{n - 1}"]["status"] = "confirmed"
    after = decided_layout(doc.topomap, decided_since=True, start=before)
    assert np.hypot(*(after[0] - after[-1])) < 0.25 * np.hypot(*(before[0] - before[-1]))


def test_positions_the_pose_graph_estimated_are_used_until_a_decision_changes():
    n = 30
    doc = make_doc(None, [(0, n - 1, "auto")], n=n)
    t = np.linspace(0, 2 * np.pi, n)
    doc.topomap.set_positions(5 * np.cos(t), 5 * np.sin(t))
    doc.topomap.graph.graph["positions"] = "estimated"
    assert np.allclose(decided_layout(doc.topomap), np.stack([5 * np.cos(t), 5 * np.sin(t)], axis=1))
    assert not np.allclose(decided_layout(doc.topomap, decided_since=True)[:, 0], 5 * np.cos(t))
