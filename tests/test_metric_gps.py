"""The recording's own GPS in the pose graph (engine/metric.py): GoPro GPMF fixes with their
precision, photo-folder fixes with the default sigma; the nodes keep the GPS, not the estimate,
as the positions ``eval`` may read."""

from __future__ import annotations

from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from engine.metric import GPS_MAX_GAP_S, gps_at, gpmf_dop_at, read_metric
from engine.poses import Poses

av = pytest.importorskip("av")

import cam360_clips as clips  # noqa: E402

LAT0, LON0 = 45.5, 7.25


@pytest.fixture(scope="module")
def gopro_clip(tmp_path_factory) -> Path:
    """3 s walking north, 2.2 m a second; DOP 1.5 (GPSP 150), the first second without a fix."""
    gps = [(LAT0 + k * 2e-5, LON0, 300.0, 3, 150) for k in range(30)]
    gps = [g[:3] + (0, 9999) for g in gps[:10]] + gps[10:]
    return clips.write_gopro_360(tmp_path_factory.mktemp("gps") / "GS010003.360", frames=30, gps=gps)


def test_a_gopro_clip_maps_with_its_gps_in_the_pose_graph_and_keeps_the_gps_on_its_nodes(gopro_clip, tmp_path,
                                                                                         capsys):
    from engine.cli import main
    from engine.graph import TopoMap

    out = tmp_path / "m.graphml"
    code = main(["map", str(gopro_clip), "-o", str(out), "--no-cache", "--input-height", "32", "--interval", "0.2"])
    said = capsys.readouterr()
    assert code == 0, said.err
    assert "GPS positions on 10 of 15 frames, each with its DOP, in the pose graph" in said.out
    g = nx.read_graphml(out)
    assert g.graph["metric"] == "gps" and g.graph["gps_sigma_m"] == 3.0
    assert g.graph["positions"] == "gps"               # the recording's own fixes, as before
    xy = TopoMap.read_graphml(out).positions()        # what eval reads: the fixes, not an estimate
    assert xy is not None and np.all(np.diff(xy[1]) >= 0)


def test_gpmf_precision_is_read_at_the_frames(gopro_clip):
    dop = gpmf_dop_at(gopro_clip, np.array([0.0, 1.5, 2.9]))
    np.testing.assert_allclose(dop, 1.5)               # the good fixes' DOP, even before the first
    assert gpmf_dop_at(gopro_clip.with_suffix(".bag"), np.array([0.0])) is None


def test_folder_gps_takes_the_default_sigma_and_no_position_far_from_a_fix(tmp_path):
    poses = Poses(t=np.array([0.0, 1.0, 2.0, 10.0, 11.0]), x=np.array([0.0, 1.0, 2.0, 10.0, 11.0]), y=np.zeros(5))
    stamps = np.array([0.5, 2.0, 2.0 + GPS_MAX_GAP_S + 0.5, 10.5, 11.2, -0.2])
    xy = gps_at(poses, stamps)
    np.testing.assert_allclose(xy[[0, 1, 3], 0], [0.5, 2.0, 10.5])
    assert np.isnan(xy[[2, 4, 5]]).all()          # in a gap of 7 s, after the last fix, before the first
    metric = read_metric(tmp_path, stamps, gps=poses)
    assert metric.gps_dop is None and metric.odometry is None and not metric.empty
    np.testing.assert_allclose(metric.gps_sigma(3.0, 2.0), 3.0)
    assert metric.notes == ["GPS positions on 3 of 6 frames, each with a default sigma, in the pose graph"]
    assert read_metric(tmp_path, stamps).empty            # no GPS, not a bag: nothing
