"""Second-family routes rendered and described in seconds, for tests: real local features
(``engine.features``) and a tiny grey-thumbnail global descriptor made here."""

import copy

import cv2
import numpy as np

import engine.synth2 as synth2
from engine.descriptors.base import Descriptors
from engine.features import FeatureTable, extract


_DESCRIBED: dict = {}


def described_route(route: str, seed: int = 0) -> Descriptors:
    """The route rendered and described once per test run (several test modules use the same
    routes); each call returns a copy of its own, which a test may change."""
    if (route, seed) not in _DESCRIBED:
        _DESCRIBED[route, seed] = _describe(route, seed)
    return copy.deepcopy(_DESCRIBED[route, seed])


def _describe(route: str, seed: int) -> Descriptors:
    rec = synth2.make_recording(route, seed, width=256)
    frames = list(rec.frames)
    grey = [cv2.resize(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), (32, 16), interpolation=cv2.INTER_AREA) for f in frames]
    v = np.stack([g.ravel().astype(np.float32) for g in grey])
    v -= v.mean(axis=1, keepdims=True)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    n = len(frames)
    return Descriptors(stamps=np.asarray(rec.stamps, np.float64), frames=np.arange(n), shifts=np.zeros(n, np.int64),
                       vectors=v, meta={"descriptor": "grey-thumbnail", "shift": True, "frame_width": 256,
                                        "interval": 1.0},
                       features=FeatureTable.from_list([extract(f) for f in frames]))
