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


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    from engine.synth import make_recording, write_recording

    rec = make_recording("reverse", look="indoor", seed=3, width=256, height=128, fps=2.0, max_frames=60)
    return write_recording(rec, tmp_path_factory.mktemp("video"), formats=("video",))["video"]


def test_the_method_decides_the_describe_options(video):
    """verified describes effnet-vlad standardised, the paper's methods plainly (their cosine
    thresholds were calibrated on plain descriptors); an option the user names wins."""
    from engine.pipeline import DescribeSettings

    small = {"input_height": 64}

    def photometric(params, options=small):
        descs = run(video, params, settings=DescribeSettings(options=dict(options))).descs
        return descs.meta["settings"].get("photometric", "none"), descs.meta["shift"]

    assert MapParams().method == "verified"
    assert photometric(MapParams()) == ("standardise", True)
    assert photometric(MapParams(method="ours")) == ("none", True)
    assert photometric(MapParams(method="simple")) == ("none", False)
    assert photometric(MapParams(), {**small, "photometric": "none"}) == ("none", True)
    assert photometric(MapParams(method="ours"), {**small, "photometric": "standardise"}) == ("standardise", True)


def test_method_settings_fill_only_what_the_descriptor_has_and_the_user_left_open():
    from engine.pipeline import DescribeSettings, method_settings

    verified, ours = MapParams(method="verified"), MapParams(method="ours")
    assert verified.describe_needs != ours.describe_needs
    assert ours.describe_needs == MapParams(method="shift-simple").describe_needs
    assert verified.describe_options == {"photometric": "standardise"} and ours.describe_options == {}
    user = DescribeSettings(options={"input_height": 64})
    assert method_settings(verified, user).options == {"input_height": 64, "photometric": "standardise"}
    assert method_settings(ours, user).options == {"input_height": 64}
    assert user.options == {"input_height": 64}                           # the user's settings untouched
    assert method_settings(MapParams(method="simple"), user).shift is False
    assert method_settings(verified, DescribeSettings(options={"photometric": "none"})).options == {
        "photometric": "none"}
    assert "photometric" not in method_settings(verified, DescribeSettings(descriptor="anyloc-vlad")).options


def test_a_plain_descriptors_file_still_maps_with_verified(reverse):
    """A user's .npz is what it is: only its panorama shift must fit the method."""
    assert "photometric" not in reverse.meta.get("settings", {})
    assert run(reverse, MapParams(method="verified")).topomap.node_count > 0
