import numpy as np
import pytest

from engine.errors import InputError
from engine.nodes import make_nodes


def reference_nodes(vectors: np.ndarray, th: float) -> list[int]:
    """METHOD.md section 3, literally: one row at a time."""
    nodes = [0]
    ref = 0
    for j in range(1, len(vectors)):
        if float(np.dot(vectors[ref], vectors[j])) >= th:
            continue
        nodes.append(j)
        ref = j
    return nodes


def unit(x: np.ndarray) -> np.ndarray:
    return (x / np.linalg.norm(x, axis=1, keepdims=True)).astype(np.float32)


def random_walk(rng, n: int, d: int, step: float) -> np.ndarray:
    """Slowly drifting descriptors with stops (repeated rows), like a robot that pauses."""
    steps = rng.normal(size=(n, d)) * step
    steps[rng.random(n) < 0.3] = 0.0  # the robot stands still
    return unit(rng.normal(size=(1, d)) + np.cumsum(steps, axis=0))


@pytest.mark.parametrize("seed", range(12))
def test_matches_plain_loop_on_random_walks(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    v = random_walk(rng, n, 32, step=float(rng.uniform(0.01, 0.3)))
    th = float(rng.uniform(0.5, 0.99))
    got = make_nodes(v, th)
    assert got.dtype == np.int64
    assert got.tolist() == reference_nodes(v, th)


def test_long_stop_then_every_row_a_node():
    rng = np.random.default_rng(5)
    still = np.repeat(unit(rng.normal(size=(1, 16))), 20000, axis=0)
    moving = unit(rng.normal(size=(300, 16)))  # independent rows: nearly all nodes
    v = np.concatenate([still, moving, still[:50]])
    got = make_nodes(v, 0.9)
    assert got.tolist() == reference_nodes(v, 0.9)
    assert got[0] == 0 and got[1] == 20000


def test_edges_of_the_input():
    assert make_nodes(np.zeros((0, 8), np.float32), 0.8).tolist() == []
    one = unit(np.ones((1, 8)))
    assert make_nodes(one, 0.8).tolist() == [0]
    same = np.repeat(one, 10, axis=0)
    assert make_nodes(same, 0.8).tolist() == [0]
    # Threshold above 1: every row differs "enough" and becomes a node.
    assert make_nodes(same, 1.5).tolist() == list(range(10))
    with pytest.raises(InputError):
        make_nodes(np.zeros(8, np.float32), 0.8)
