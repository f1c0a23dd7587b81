"""Descriptors from any model map: an .npz with an unknown descriptor name and no columns."""

from __future__ import annotations

import numpy as np
import pytest

from engine.benchmark import random_walk_descriptors
from engine.cli import main
from engine.descriptors.base import Descriptors
from engine.params import MapParams
from engine.pipeline import build_map, descriptor_defaults


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """600 rows of 1024-D vectors, meta descriptor "my-own-vpr", nothing else."""
    v, origin = random_walk_descriptors(600, 1024, seed=4, revisit_share=0.3)
    n = v.shape[0]
    d = Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n), shifts=np.zeros(n, np.int64),
                    vectors=v, meta={"descriptor": "my-own-vpr"})
    path = tmp_path_factory.mktemp("foreign") / "x.npz"
    d.save(path)
    return path, origin


def test_unknown_descriptor_gets_thresholds_from_the_recording(foreign):
    path, _ = foreign
    th = descriptor_defaults(Descriptors.load(path))
    assert set(th) >= {"node_sim_th", "loop_sim_th"}
    assert 0.0 < th["loop_sim_th"] < 1.0 and 0.0 < th["node_sim_th"] < 1.0


@pytest.mark.parametrize("method", ["ours", "simple", "verified"])
def test_build_map_maps_a_foreign_npz(foreign, method):
    path, origin = foreign
    descs = Descriptors.load(path)
    if method == "simple":
        descs.meta["shift"] = False
    topomap = build_map(descs, MapParams(method=method))
    assert 1 < topomap.node_count <= len(descs)


def test_cli_maps_a_foreign_npz(foreign, tmp_path, capsys):
    path, _ = foreign
    out = tmp_path / "y.graphml"
    code = main(["map", str(path), "-o", str(out), "--method", "ours", "-q"])
    assert code == 0, capsys.readouterr().err
    assert out.is_file() and "<graphml" in out.read_text()[:2000]
