"""The g2o export of the pose graph (engine/exports.py ``write_g2o``): parsed here as text and
read back by an independent reader, GTSAM's ``readG2o``, which must agree with it and with the map."""

import math

import numpy as np
import pytest
from rendered_routes import described_route

from engine.cli import main
from engine.exports import g2o_text, write_map
from engine.params import MapParams
from engine.pipeline import build_map


@pytest.fixture(scope="module")
def described(tmp_path_factory):
    descs = described_route("reverse")
    path = tmp_path_factory.mktemp("g2o") / "reverse.npz"
    descs.save(path)
    return descs, path


@pytest.fixture(scope="module")
def mapped(described, tmp_path_factory):
    topomap = build_map(described[0], MapParams(neighbor_node_num=5))
    path = tmp_path_factory.mktemp("g2o_out") / "map.g2o"
    write_map(topomap, path)          # by extension, as 'panotopo map -o map.g2o' does
    return topomap, path


def _parse(path):
    return _parse_text(path.read_text())


def _parse_text(text):
    vertices, edges = {}, []
    for line in text.splitlines():
        tag, *rest = line.split()
        if tag == "VERTEX_SE2":
            vertices[int(rest[0])] = tuple(map(float, rest[1:4]))
        else:
            assert tag == "EDGE_SE2" and len(rest) == 11     # i j dx dy dtheta + 6 information numbers
            edges.append((int(rest[0]), int(rest[1]), tuple(map(float, rest[2:5])), tuple(map(float, rest[5:]))))
    return vertices, edges


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_the_g2o_file_holds_the_estimated_poses_the_steps_and_the_kept_loops(mapped):
    topomap, path = mapped
    vertices, edges = _parse(path)
    g = topomap.graph
    assert sorted(vertices) == list(range(topomap.node_count))
    for n, d in g.nodes(data=True):
        x, y, th = vertices[d["index"]]
        assert x == pytest.approx(d["x"], abs=1e-6) and y == pytest.approx(d["y"], abs=1e-6)
        assert abs(_wrap(th - math.radians(d["heading"]))) < 1e-6
    pairs = {(i, j) for i, j, _, _ in edges}
    apart = {}   # the two views' measured distance of each loop, None where not measured
    for u, v, d in g.edges(data=True):
        if d.get("kind") == "loop":
            i, j = sorted((g.nodes[u]["index"], g.nodes[v]["index"]))
            apart[(i, j)] = d.get("distance_steps")
    kept = topomap.loops(("auto", "confirmed", "manual"))
    assert kept, "the drive back closes loops"
    expected = {(k, k + 1) for k in range(topomap.node_count - 1)}
    expected |= {(g.nodes[u]["index"], g.nodes[v]["index"]) for u, v, _ in kept}
    assert pairs == expected and len(edges) == len(expected)
    for i, j, (dx, dy, dt), info in edges:
        m = np.array([[info[0], info[1], info[2]], [info[1], info[3], info[4]], [info[2], info[4], info[5]]])
        assert np.all(np.linalg.eigvalsh(m) > 0)          # an information matrix
        if (i, j) in apart:   # a loop: b where the two views measured it, on a where they did not
            assert math.hypot(dx, dy) == pytest.approx(apart[(i, j)] or 0.0, abs=1e-6)
    # the solution agrees with its steps: the estimated poses of consecutive nodes (where no
    # loop bends the path) are about one measured step apart
    steps = [math.hypot(dx, dy) for i, j, (dx, dy, _), _ in edges if j == i + 1]
    moved = [math.hypot(vertices[i + 1][0] - vertices[i][0], vertices[i + 1][1] - vertices[i][1])
             for i, j, _, _ in edges if j == i + 1]
    assert np.median(np.abs(np.array(steps) - np.array(moved))) < 0.2


def test_gtsam_reads_the_same_graph_back(mapped):
    import gtsam

    topomap, path = mapped
    vertices, edges = _parse(path)
    graph, initial = gtsam.readG2o(str(path), False)
    assert initial.size() == len(vertices) and graph.size() == len(edges)
    for k, (x, y, th) in vertices.items():
        p = initial.atPose2(k)
        assert (p.x(), p.y()) == pytest.approx((x, y), abs=1e-6) and abs(_wrap(p.theta() - th)) < 1e-6
    for f, (i, j, (dx, dy, dt), info) in zip((graph.at(k) for k in range(graph.size())), edges):
        assert list(f.keys()) == [i, j]
        z = f.measured()
        assert (z.x(), z.y()) == pytest.approx((dx, dy), abs=1e-6) and abs(_wrap(z.theta() - dt)) < 1e-6
        read = np.asarray(f.noiseModel().information())
        assert read[np.triu_indices(3)] == pytest.approx(np.array(info), rel=1e-5)


def test_a_map_without_a_pose_graph_is_one_line(described, tmp_path, capsys):
    rc = main(["map", str(described[1]), "-o", str(tmp_path / "m.g2o"), "--method", "shift-simple", "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "g2o" in err and "Traceback" not in err


def test_a_recording_shorter_than_the_temporal_window_still_gets_its_path_poses(described):
    """No pair lies beyond the temporal window, so there is no loop; the pose graph of the
    steps alone still gives every node a pose, one step apart where the camera moved."""
    descs = described[0]
    topomap = build_map(descs, MapParams(neighbor_node_num=len(descs)))
    assert not [e for e in topomap.graph.edges(data=True) if e[2].get("kind") == "loop"]
    x, y = topomap.positions(estimated=True)
    gaps = np.hypot(np.diff(x), np.diff(y))
    assert np.all(gaps < 1.5) and np.median(gaps) > 0.5


def test_a_metric_map_weighs_its_loops_against_its_steps_as_the_image_only_map_does(described):
    """With odometry the pose graph is in metres and its loop sigma is ``loop_sigma_steps``
    node steps long in metres; the g2o file must say the same, or a reader's solver would trust
    the loops far more than panotopo's did."""
    from engine.metric import Metric
    from engine.synth2.recording import poses_for

    descs = described[0]
    truth = poses_for("reverse")
    odometry = np.stack([truth.x, truth.y, truth.yaw], axis=1)[: len(descs)]
    params = MapParams(neighbor_node_num=5)
    topomap = build_map(descs, params, metric=Metric(odometry=odometry))
    vertices, edges = _parse_text(g2o_text(topomap))
    steps = [math.hypot(dx, dy) for i, j, (dx, dy, _), _ in edges if j == i + 1]
    loops = [info for i, j, _, info in edges if j != i + 1]
    assert loops, "the drive back closes loops"
    step_length = float(np.median(steps))
    assert 0.3 < step_length < 3.0          # metres: frames 0.8 m apart
    for info in loops:
        sigma_in_steps = 1.0 / math.sqrt(info[0]) / step_length
        assert sigma_in_steps == pytest.approx(params.loop_sigma_steps, rel=0.05)
