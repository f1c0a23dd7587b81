"""Loop detection: the paper's three methods (``paper``) and ``verified`` (``verified``: the
stages of this package, in the order they run). ``LoopCandidate`` is what every method returns."""

from __future__ import annotations

import numpy as np

from ..params import MapParams
from .pairs import LoopCandidate
from .paper import similarity_matrix


def detect_loops(node_vectors: np.ndarray, params: MapParams, **context) -> list[LoopCandidate]:
    """Loop candidates of ``params.method`` on node descriptors, sorted by (a, b). ``verified``
    on descriptors alone (no ``context``: no geometry, no pose graph) or with the recording's
    ``engine.loops.verified.detect_loops`` context (node_rows, features, ...)."""
    from . import paper

    if params.method != "verified":
        return paper.detect_loops(node_vectors, params, **context)
    from .verified import detect_loops as verified

    v = np.asarray(node_vectors, np.float32)
    context.setdefault("node_rows", np.arange(v.shape[0]))
    return verified(v, params, **context).loops


__all__ = ["LoopCandidate", "detect_loops", "similarity_matrix"]
