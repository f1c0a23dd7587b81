"""A bag's odometry topic in the pose graph (engine/sources/odometry.py, engine/metric.py):
bags written here with rosbags' writers (ROS1 .bag, whose connection type is spelled
``nav_msgs/Odometry``; ROS2 sqlite3 and MCAP), frames from a synthetic route."""

from __future__ import annotations

import math
from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from engine.cli import main
from engine.errors import InputError
from engine.sources.odometry import MAX_GAP_S, Odometry, read_odometry

FAST = ["--input-height", "64", "--no-cache"]
# The odometry frame: where the robot's odometry put its start (x, y metres, yaw radians).
ORIGIN = (5.0, -3.0, math.radians(30.0))


@pytest.fixture(scope="module")
def route():
    from engine.synth.recording import make_recording

    rec = make_recording("loop", "indoor", seed=0, width=256, height=128, fps=2.0, max_frames=50)
    return list(rec.frames), np.asarray(rec.stamps) + 100.0, rec.poses


def _odometry_track(poses, t0: float, t1: float, rate: float = 20.0):
    """(t, x, y, yaw) of the route's poses in the odometry frame, at ``rate`` Hz over [t0, t1]
    (bag time: the route's stamps + 100 s)."""
    t = np.arange(t0, t1 + 1e-9, 1.0 / rate)
    local = t - 100.0
    x = np.interp(local, poses.t, poses.x)
    y = np.interp(local, poses.t, poses.y)
    yaw = np.interp(local, poses.t, np.unwrap(poses.yaw))
    c, s = math.cos(ORIGIN[2]), math.sin(ORIGIN[2])
    return t, ORIGIN[0] + c * x - s * y, ORIGIN[1] + s * x + c * y, yaw + ORIGIN[2]


def write_bag(path: Path, frames, stamps, pose_topics: dict, kind: str = "ros1") -> Path:
    """A bag of compressed images on /cam and ``pose_topics`` {topic: (msgtype, (t, x, y, yaw))};
    ``kind`` "ros1" (.bag), "sqlite3" or "mcap" (ROS2)."""
    import cv2
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types

    def header(t):
        ns = int(round(t * 1e9))
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), stamp=stamp, frame_id="f")

    def pose(x, y, yaw):
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))

    def odometry(t, x, y, yaw):
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return T["nav_msgs/msg/Odometry"](
            header=header(t), child_frame_id="base",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose(x, y, yaw), covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))

    msgs = []
    for rgb, t in zip(frames, stamps):
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        msgs.append((t, "/cam", "sensor_msgs/msg/CompressedImage",
                     T["sensor_msgs/msg/CompressedImage"](header=header(t), format="jpeg", data=buf.reshape(-1))))
    for topic, (msgtype, track) in pose_topics.items():
        for t, x, y, yaw in zip(*track):
            msg = (odometry(t, x, y, yaw) if msgtype == "nav_msgs/msg/Odometry" else
                   T["geometry_msgs/msg/PoseStamped"](header=header(t), pose=pose(x, y, yaw)))
            msgs.append((t, topic, msgtype, msg))
    msgs.sort(key=lambda m: m[0])
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=plugin)
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    with writer:
        conns = {}
        for t, topic, msgtype, msg in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], int(round(t * 1e9)), serialize(msg, msgtype))
    return path


def _nodes(path: Path):
    g = nx.read_graphml(path)
    return g, sorted((d for _, d in g.nodes(data=True)), key=lambda d: d["index"])


@pytest.mark.parametrize("kind, msgtype", [("ros1", "nav_msgs/msg/Odometry"),
                                            ("sqlite3", "geometry_msgs/msg/PoseStamped"),
                                            ("mcap", "nav_msgs/msg/Odometry")])
def test_node_poses_follow_the_odometry(route, tmp_path, capsys, kind, msgtype):
    frames, stamps, poses = route
    track = _odometry_track(poses, stamps[0] - 0.3, stamps[-1] + 0.3)
    bag = write_bag(tmp_path / ("r.bag" if kind == "ros1" else "r2"), frames, stamps, {"/odom": (msgtype, track)}, kind)
    if kind == "ros1":   # ROS1's own spelling of the type, as rosbag record writes it
        assert b"type=nav_msgs/Odometry" in bag.read_bytes()
    out = tmp_path / "m.graphml"
    assert main(["map", str(bag), "-o", str(out), *FAST]) == 0
    said = capsys.readouterr().out
    assert f"odometry from /odom ({msgtype}" in said            # which topic, in one line
    g, nodes = _nodes(out)
    assert g.graph["positions"] == "estimated" and g.graph["metric"] == "odometry"
    t = np.array([d["stamp"] for d in nodes])
    x, y = np.interp(t, track[0], track[1]), np.interp(t, track[0], track[2])
    yaw = np.degrees(np.interp(t, track[0], track[3]))
    loops = [e for e in g.edges(data=True) if e[2]["kind"] == "loop"]
    tol = 0.05 if not loops else 0.5
    assert np.max(np.hypot([d["x"] for d in nodes] - x, [d["y"] for d in nodes] - y)) < tol
    turn = (np.array([d["heading"] for d in nodes]) - yaw + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(turn)) < 2.0
    assert np.ptp(x) > 5.0                                      # the route does go somewhere


def test_a_topic_that_does_not_cover_the_images_is_refused_in_one_line(route, tmp_path, capsys):
    frames, stamps, poses = route
    half = stamps[len(stamps) // 2]
    track = _odometry_track(poses, stamps[0], half)
    bag = write_bag(tmp_path / "half.bag", frames, stamps, {"/odom": ("nav_msgs/msg/Odometry", track)})
    for extra in ([], ["--odom-topic", "/odom"]):
        code = main(["map", str(bag), "-o", str(tmp_path / "m.graphml"), *FAST, "-q", *extra])
        err = capsys.readouterr().err
        assert code != 0
        assert err.count("\n") == 1 and "does not cover the images" in err and "--odom-topic none" in err
    # said so, the map is made from the images alone
    assert main(["map", str(bag), "-o", str(tmp_path / "m.graphml"), *FAST, "-q", "--odom-topic", "none"]) == 0
    g, _ = _nodes(tmp_path / "m.graphml")
    assert "metric" not in g.graph


def test_several_odometry_topics_none_chosen_unless_named(route, tmp_path, capsys):
    frames, stamps, poses = route
    track = _odometry_track(poses, stamps[0] - 0.1, stamps[-1] + 0.1, rate=5.0)
    doubled = (track[0], 2 * track[1], 2 * track[2], track[3])
    bag = write_bag(tmp_path / "two.bag", frames, stamps, {"/odom": ("nav_msgs/msg/Odometry", track),
                                                           "/slam": ("geometry_msgs/msg/PoseStamped", doubled)})
    out = tmp_path / "m.graphml"
    fast = ["--input-height", "64", "--cache-dir", str(tmp_path / "cache")]   # described once
    assert main(["map", str(bag), "-o", str(out), *fast]) == 0
    err = capsys.readouterr().err
    assert "several odometry topics (/odom, /slam)" in err and "--odom-topic" in err
    assert "metric" not in _nodes(out)[0].graph
    assert main(["map", str(bag), "-o", str(out), *fast, "--odom-topic", "/slam"]) == 0
    assert "odometry from /slam" in capsys.readouterr().out
    g, nodes = _nodes(out)
    t = np.array([d["stamp"] for d in nodes])
    x = np.interp(t, doubled[0], doubled[1])
    assert g.graph["metric"] == "odometry" and np.allclose([d["x"] for d in nodes], x, atol=0.5)
    code = main(["map", str(bag), "-o", str(out), *fast, "--odom-topic", "/nope"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "no odometry topic '/nope'" in err and "/odom, /slam" in err


def test_an_odometry_topic_for_a_recording_without_topics_is_refused(route, tmp_path, capsys):
    from engine.synth.writers import write_image_folder

    frames, stamps, _ = route
    folder = write_image_folder(tmp_path / "frames", frames[:8], list(stamps[:8]))
    code = main(["map", str(folder), "-o", str(tmp_path / "m.graphml"), *FAST, "--odom-topic", "/odom"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "only ROS bags have topics" in err


def test_poses_are_interpolated_in_time_and_on_the_circle():
    odo = Odometry("/odom", "nav_msgs/msg/Odometry", t=np.array([10.0, 10.5, 11.0]), x=np.array([0.0, 1.0, 3.0]),
                   y=np.zeros(3), yaw=np.unwrap(np.radians([170.0, -170.0, -150.0])))
    at = odo.at(np.array([10.25, 10.75, 10.0 - MAX_GAP_S]))
    np.testing.assert_allclose(at[:, 0], [0.5, 2.0, 0.0])
    assert np.cos(at[0, 2]) == pytest.approx(-1.0) and np.degrees(at[1, 2]) == pytest.approx(-160.0)   # 180, -160
    with pytest.raises(InputError, match="does not cover the images"):
        odo.at(np.array([10.2, 12.5]))


def test_a_fast_topic_is_read_at_twenty_hertz(route, tmp_path):
    frames, stamps, poses = route
    track = _odometry_track(poses, stamps[0], stamps[-1], rate=100.0)
    bag = write_bag(tmp_path / "fast.bag", frames[:2], stamps[:2], {"/odom": ("nav_msgs/msg/Odometry", track)})
    odo, line = read_odometry(bag)
    assert odo is not None and "/odom" in line
    assert np.median(np.diff(odo.t)) == pytest.approx(0.05, abs=0.011)
    assert odo.t.size < 0.25 * track[0].size


def test_an_odometry_topic_is_for_the_verified_method(route, tmp_path, capsys):
    frames, stamps, poses = route
    track = _odometry_track(poses, stamps[0], stamps[7])
    bag = write_bag(tmp_path / "r.bag", frames[:8], stamps[:8], {"/odom": ("nav_msgs/msg/Odometry", track)})
    code = main(["map", str(bag), "-o", str(tmp_path / "m.graphml"), *FAST, "--method", "ours", "--odom-topic", "/odom"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "verified" in err
    assert main(["map", str(bag), "-o", str(tmp_path / "m.graphml"), *FAST, "--method", "ours"]) == 0
    assert "odometry from" not in capsys.readouterr().out   # the paper's methods have no pose graph to put it in
