"""engine.run: describe, map, position and evaluate in one call (CLI, app worker, benchmarks)."""

import numpy as np
import pytest
from rendered_routes import described_route

import engine.synth2 as synth2
from engine.errors import InputError
from engine.params import MapParams
from engine.poses import Poses
from engine.run import run


@pytest.fixture(scope="module")
def reverse():
    return described_route("reverse")


def test_one_call_maps_positions_and_evaluates(reverse):
    poses = synth2.poses_for("reverse", 0)
    out = run(reverse, MapParams(neighbor_node_num=5), poses=poses, evaluate=True)
    x, y = poses.at(out.topomap.stamps())
    nodes = sorted(out.topomap.graph.nodes(data=True), key=lambda n: n[1]["index"])
    assert np.allclose([d["x"] for _, d in nodes], x) and np.allclose([d["y"] for _, d in nodes], y)
    assert out.evaluation is not None and out.evaluation.events_total >= 1
    assert out.evaluation.fp == 0 and out.evaluation.events_found == out.evaluation.events_total


def test_poses_that_do_not_cover_the_recording_are_one_clear_error(reverse):
    short = Poses(t=np.array([0.0, 1.0]), x=np.zeros(2), y=np.zeros(2))
    with pytest.raises(InputError, match="my-poses"):
        run(reverse, MapParams(), poses=short, poses_name="my-poses")


def test_without_poses_there_is_a_map_and_no_evaluation(reverse):
    out = run(reverse, MapParams(), evaluate=True)
    assert out.topomap.node_count > 0 and out.evaluation is None and out.poses is None
