import numpy as np
import pytest

from engine.errors import InputError
from engine.loops import LoopCandidate, detect_loops, similarity_matrix
from engine.params import MapParams


def unit(x: np.ndarray) -> np.ndarray:
    return (x / np.linalg.norm(x, axis=1, keepdims=True)).astype(np.float32)


def reference_ours(v: np.ndarray, th: float, window_size: int, count_th: int, nn: int) -> dict:
    """METHOD.md section 4 in plain loops: {(a, b): window_count} of mutual pairs, b - a >= 2."""
    m = len(v)
    sim = lambda i, j: float(np.dot(v[i], v[j]))  # noqa: E731
    stored: dict[tuple[int, int], int] = {}
    for q in range(m):
        for s in range(0, m - window_size + 1):
            window = range(s, s + window_size)
            # Skip a window holding the query or one of its temporal neighbours.
            if any(abs(t - q) <= nn for t in window):
                continue
            count = sum(1 for t in window if sim(q, t) >= th)
            if count > count_th:
                best = window[0]
                for t in window:
                    if sim(q, t) > sim(q, best):
                        best = t
                stored[(q, best)] = max(stored.get((q, best), 0), count)
    loops = {}
    for (q, c), n in stored.items():
        if q < c and (c, q) in stored and c - q >= 2:
            loops[(q, c)] = max(n, stored[(c, q)])
    return loops


def reference_simple(v: np.ndarray, th: float) -> set:
    m = len(v)
    return {(i, j) for i in range(m) for j in range(i + 2, m) if float(np.dot(v[i], v[j])) >= th}


def smooth_sequence(rng, n: int, d: int, rho: float) -> np.ndarray:
    """Unit descriptors whose similarity decays like rho ** gap: dense nodes along a path."""
    x = np.empty((n, d))
    x[0] = rng.normal(size=d)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + np.sqrt(1 - rho**2) * rng.normal(size=d)
    return unit(x)


def route_with_revisit(rng, d: int = 256) -> tuple[np.ndarray, tuple[int, int], int]:
    """A path of places, a detour of new places, then a stretch of the first places again.

    Neighbouring nodes look alike (as with nodes about a metre apart), so a window
    at the revisit holds several matches. Returns the node descriptors, the offsets
    (first visit, second visit) of the revisited stretch, and its length.
    """
    first_len = int(rng.integers(14, 25))
    detour = int(rng.integers(10, 20))
    places = smooth_sequence(rng, first_len + detour, d, rho=0.8)
    revisit_len = int(rng.integers(7, 11))
    start = int(rng.integers(0, first_len - revisit_len))
    noise = 0.3 / np.sqrt(d) * rng.normal(size=(revisit_len, d))
    again = unit(places[start:start + revisit_len] + noise)
    return np.concatenate([places, again]), (start, first_len + detour), revisit_len


def params(method="ours", th=0.5, w=5, c=2, nn=3) -> MapParams:
    return MapParams(method=method, node_sim_th=0.8, loop_sim_th=th, window_size=w,
                     count_th=c, neighbor_node_num=nn)


@pytest.mark.parametrize("w,c,nn", [(5, 2, 3), (3, 1, 1), (4, 0, 0), (1, 0, 2), (6, 3, 5), (5, 4, 2)])
@pytest.mark.parametrize("seed", range(6))
def test_ours_equals_reference_on_random_inputs(w, c, nn, seed):
    rng = np.random.default_rng(seed * 100 + w * 10 + c)
    m = int(rng.integers(1, 40))
    # Low dimension so random pairs often pass the threshold: many windows, many ties to check.
    v = unit(rng.normal(size=(m, 3)))
    th = float(rng.uniform(0.0, 0.8))
    got = detect_loops(v, params(th=th, w=w, c=c, nn=nn))
    expect = reference_ours(v, th, w, c, nn)
    assert {(l.a, l.b): l.window_count for l in got} == expect


@pytest.mark.parametrize("seed", range(8))
def test_ours_finds_planted_revisit(seed):
    rng = np.random.default_rng(seed)
    v, (first, second), length = route_with_revisit(rng)
    for w, c, nn in [(5, 2, 3), (3, 1, 2), (4, 2, 4)]:
        got = detect_loops(v, params(th=0.6, w=w, c=c, nn=nn))
        pairs = {(l.a, l.b): l.window_count for l in got}
        assert pairs == reference_ours(v, 0.6, w, c, nn)
        # The middle of the revisited stretch sits in a window full of matches.
        assert (first + length // 2, second + length // 2) in pairs
        for a, b in pairs:  # every loop lies on the revisit, give or take a neighbour
            assert first - 2 <= a < first + length + 2 and abs((b - second) - (a - first)) <= 1
        assert all(c < n <= w for n in pairs.values())


@pytest.mark.parametrize("method", ["simple", "shift-simple"])
@pytest.mark.parametrize("seed", range(5))
def test_simple_is_every_pair_over_threshold(method, seed):
    rng = np.random.default_rng(seed)
    v = unit(rng.normal(size=(int(rng.integers(2, 60)), 4)))
    th = float(rng.uniform(0.2, 0.9))
    got = detect_loops(v, params(method=method, th=th))
    assert {(l.a, l.b) for l in got} == reference_simple(v, th)
    assert all(l.window_count == 0 for l in got)


def test_candidates_are_sorted_with_true_similarity():
    rng = np.random.default_rng(3)
    v, _, _ = route_with_revisit(rng)
    got = detect_loops(v, params(method="simple", th=0.6))
    assert got, "the planted revisit gives loops"
    assert [(l.a, l.b) for l in got] == sorted((l.a, l.b) for l in got)
    for l in got:
        assert l.a < l.b
        assert l.similarity == pytest.approx(float(v[l.a] @ v[l.b]), abs=1e-6)
        assert l.yaw is None and l.score is None


def test_ours_blocks_give_same_answer_as_one_block(monkeypatch):
    import engine.loops as loops

    rng = np.random.default_rng(9)
    v, _, _ = route_with_revisit(rng)
    whole = detect_loops(v, params(th=0.55))
    monkeypatch.setattr(loops.paper, "_BLOCK_ELEMENTS", 1)  # 16-row blocks
    assert detect_loops(v, params(th=0.55)) == whole
    assert whole


def test_similarity_matrix():
    rng = np.random.default_rng(1)
    v = unit(rng.normal(size=(7, 5)))
    s = similarity_matrix(v)
    assert s.shape == (7, 7) and s.dtype == np.float32
    assert np.allclose(np.diag(s), 1.0, atol=1e-6)
    assert s[2, 5] == pytest.approx(float(v[2] @ v[5]), abs=1e-6)


def test_bad_parameters_and_tiny_inputs():
    v = unit(np.random.default_rng(0).normal(size=(4, 3)))
    assert detect_loops(v, params(w=5)) == []  # fewer nodes than one window
    assert detect_loops(np.zeros((0, 3), np.float32), params()) == []
    with pytest.raises(InputError, match="loop_sim_th"):
        detect_loops(v, MapParams(method="ours", loop_sim_th=None))
    with pytest.raises(InputError, match="method"):
        detect_loops(v, params(method="magic"))
    with pytest.raises(InputError):
        detect_loops(v, params(w=0))
    assert isinstance(LoopCandidate(0, 2, 0.5, 3), LoopCandidate)


@pytest.mark.parametrize("w,c,nn", [(5, 2, 3), (3, 0, 0), (20, 3, 2), (17, 16, 1), (2, 1, 30)])
@pytest.mark.parametrize("seed", range(3))
def test_ours_small_tiles_equal_reference(monkeypatch, w, c, nn, seed):
    """Tiles of 16 nodes (windows and neighbourhoods reaching across several tiles, the
    transposed half of each tile) give the plain loops' answer."""
    import engine.loops as loops

    monkeypatch.setattr(loops.paper, "_BLOCK_ELEMENTS", 1)
    assert loops.paper._tile_side() == 16
    rng = np.random.default_rng(seed * 1000 + w * 10 + c)
    m = int(rng.integers(40, 90))
    v = unit(rng.normal(size=(m, 3)))
    th = float(rng.uniform(0.0, 0.7))
    got = detect_loops(v, params(th=th, w=w, c=c, nn=nn))
    assert {(l.a, l.b): l.window_count for l in got} == reference_ours(v, th, w, c, nn)


def test_ours_reports_progress_per_tile_and_can_be_cancelled(monkeypatch):
    import threading

    import engine.loops as loops
    from engine.errors import Cancelled

    monkeypatch.setattr(loops.paper, "_BLOCK_ELEMENTS", 1)  # 16-node tiles
    v, _, _ = route_with_revisit(np.random.default_rng(2))
    calls = []
    whole = detect_loops(v, params(th=0.55), progress=lambda *a: calls.append(a))
    assert {stage for _, _, stage in calls} == {loops.paper.OURS_STAGE}
    done = [d for d, _, _ in calls]
    total = calls[-1][1]
    assert done == sorted(done) and done[0] == 0 and done[-1] == total > 1
    # The same through the context the command line sets; the answer does not change.
    seen = []
    with loops.paper.loop_progress(lambda *a: seen.append(a)):
        assert detect_loops(v, params(th=0.55)) == whole
    assert seen == calls
    stop = threading.Event()
    stop.set()
    with pytest.raises(Cancelled):
        detect_loops(v, params(th=0.55), cancel=stop)


def test_simple_reports_progress():
    import engine.loops as loops

    v = unit(np.random.default_rng(4).normal(size=(30, 4)))
    calls = []
    detect_loops(v, params(method="simple", th=0.5), progress=lambda *a: calls.append(a))
    assert calls[-1] == (30, 30, loops.paper.SIMPLE_STAGE)


@pytest.mark.parametrize("seed", range(3))
def test_ours_tiles_agree_exactly_when_the_arithmetic_is_exact(monkeypatch, seed):
    """Vectors of eighths: every similarity is exact in float32 whatever the product's blocking,
    so tiles of 16 nodes and one big tile must agree to the pair and the count (many ties
    too). With real-valued vectors a pair within a rounding error of loop_sim_th may differ
    between blockings of the matrix product (the previous row-block code did the same)."""
    import engine.loops as loops

    rng = np.random.default_rng(seed)
    m, d = 300, int(rng.integers(4, 16))
    v = (np.clip(np.cumsum(rng.integers(-1, 2, size=(m, d)), axis=0), -8, 8) / 8).astype(np.float32)
    th = float(np.quantile(v @ v.T, 0.8))
    p = params(th=th, w=int(rng.integers(3, 8)), c=2, nn=int(rng.integers(0, 6)))
    whole = loops.paper._ours_pairs(v, p)
    monkeypatch.setattr(loops.paper, "_BLOCK_ELEMENTS", 1)
    tiled = loops.paper._ours_pairs(v, p)
    assert whole[0].size > 0
    for a, b in zip(whole, tiled):
        assert np.array_equal(a, b)
