"""The fast paths of mapping at scale (benchmarks/bench_scale.py) give what the plain ones gave:
the streamed GraphML writer writes networkx's bytes, one pair per place is the greedy search it
replaced, support along the stretch and its cache are the per-pair mean."""

import io

import networkx as nx
import numpy as np

from engine import retrieval as R
from engine.graph import TopoMap, _write_graphml
from engine.loops.pairs import Pairs
from engine.loops.places import one_per_place
from engine.loops.retrieve import with_support
from engine.params import MapParams
from tests.test_graph import small_map


def _both(g: nx.Graph) -> tuple[bytes, bytes]:
    ours, theirs = io.BytesIO(), io.BytesIO()
    _write_graphml(g, ours)
    nx.write_graphml(g.copy(), theirs, infer_numeric_types=False)
    return ours.getvalue(), theirs.getvalue()


def test_streamed_graphml_is_networkx_byte_for_byte():
    tm = small_map()
    tm.set_label("n3", 'a <b> & "c"\n\tline')
    tm.set_status("n3", "n16", "rejected")
    for keep in (False, True):
        ours, theirs = _both(tm.corrected(keep_rejected=keep))
        assert ours == theirs
    g = nx.Graph(generator="panotopo x", id="g&1", empty="", odd="\ud800")
    g.add_node("n0", index=0, kind=1)
    g.add_node('n"1')                          # no attributes: an empty element
    g.add_edge("n0", 'n"1', kind="loop", w=float("nan"))
    g.add_edge("n0", "n2")
    assert _both(g)[0] == _both(g)[1]
    assert _both(nx.Graph())[0] == _both(nx.Graph())[1]
    assert _both(nx.Graph(generator="x"))[0] == _both(nx.Graph(generator="x"))[1]


def test_written_map_reads_back(tmp_path):
    tm = small_map()
    tm.write_graphml(tmp_path / "m.graphml")
    back = TopoMap.read_graphml(tmp_path / "m.graphml")
    assert sorted(back.graph.edges) == sorted(tm.corrected().edges)
    assert back.graph.nodes["n4"] == tm.graph.nodes["n4"]


def _greedy(a, b, confidence, r):
    """One pair per place as it was: in confidence order, kept unless near a kept pair."""
    kept, keep = [], np.zeros(a.size, bool)
    for i in np.lexsort((b, a, -confidence)):
        if not any(abs(a[i] - u) <= r and abs(b[i] - w) <= r for u, w in kept):
            keep[i] = True
            kept.append((a[i], b[i]))
    return keep


def test_one_per_place_is_the_greedy_search():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 300, 2000)
    b = a + rng.integers(6, 60, 2000)
    pair = np.unique(a * 1000 + b)
    a, b = pair // 1000, pair % 1000
    for confidence in (rng.normal(size=a.size), np.round(rng.normal(size=a.size))):   # ties too
        p = Pairs(a=a, b=b, cosine=np.zeros(a.size, np.float32), score=confidence, confidence=confidence)
        for r in (0, 1, 4, 9):
            owner = one_per_place(p, r)
            kept = owner == np.arange(a.size)
            assert np.array_equal(kept, _greedy(a, b, confidence, r))
            # each pair set aside names a kept pair of its place, one at least as confident
            assert kept[owner].all() and (np.abs(a[owner] - a) <= r).all() and (np.abs(b[owner] - b) <= r).all()
            assert (confidence[owner] >= confidence).all()


def test_sorted_unique_is_np_unique():
    x = np.random.default_rng(1).integers(0, 50, 400)
    assert np.array_equal(R.sorted_unique(x), np.unique(x))
    assert R.sorted_unique(np.zeros(0, np.int64)).size == 0


def test_support_is_the_per_pair_mean_and_the_cache_gives_the_same():
    rng = np.random.default_rng(2)
    v = rng.normal(size=(300, 16)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    rec = np.zeros(300, np.int64)
    params = MapParams()
    a = rng.integers(0, 290, 500)
    b = np.minimum(a + rng.integers(6, 40, 500), 299)
    stats = R.background(v, params.neighbor_node_num)
    h = params.support_half
    for d in (1, -1):   # each pair alone: no pair shared with another's stretch
        mean, count = R.diagonal_support(v, stats, a, b, h, d)
        alone = [R.diagonal_support(v, stats, a[i:i + 1], b[i:i + 1], h, d) for i in range(a.size)]
        assert np.array_equal(mean, np.concatenate([m for m, _ in alone]), equal_nan=True)
        assert np.array_equal(count, np.concatenate([c for _, c in alone]))
    cache = {}
    pairs = lambda k: Pairs(a=a[k], b=b[k], cosine=np.zeros(k.size, np.float32),   # noqa: E731
                            score=np.zeros(k.size))
    first = with_support(v, rec, pairs(np.arange(0, 500, 2)), params, cache)
    again = with_support(v, rec, pairs(np.arange(500)), params, cache)       # half of them cached
    fresh = with_support(v, rec, pairs(np.arange(500)), params, {})
    assert np.array_equal(again.support, fresh.support, equal_nan=True)
    assert np.array_equal(again.direction, fresh.direction)
    assert np.array_equal(first.support, fresh.support[::2], equal_nan=True)


def test_a_numpy_number_or_a_bool_on_the_map_is_written_as_its_plain_value(tmp_path):
    """Values set by hand as numpy numbers or bools are stored as the plain values the GraphML
    contract names (int, float; bools as 0/1), never an export that fails."""
    g = nx.Graph(generator="x", flag=True)
    g.add_node("n0", index=np.int64(3), x=np.float32(1.5))
    g.add_edge("n0", "n0", similarity=np.float64(0.25))
    f = io.BytesIO()
    _write_graphml(g, f)
    back = nx.read_graphml(io.BytesIO(f.getvalue()))
    assert back.graph["flag"] == 1 and back.nodes["n0"] == {"index": 3, "x": 1.5}
    assert back.edges["n0", "n0"]["similarity"] == 0.25
