"""The panorama shift from the camera's recorded heading (issue 44 item 6).

``shift_from_heading`` / ``shift_from_yaw`` are checked against the synthetic renderer's own
convention (centre column = heading, columns increase clockwise), not against themselves;
bags carry the heading in an Odometry or Imu topic (written with rosbags), photo folders in
EXIF GPSImgDirection (written with Pillow).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, TiffImagePlugin

from engine.errors import InputError
from engine.poses import Poses
from engine.shift import apply_shift, shift_from_heading, shift_from_yaw
from engine.sources import BagSource, FolderSource
from engine.sources.orientation import headings_at
from engine.synth.render import render
from engine.synth.routes import make_route
from engine.synth.writers import write_ros1_bag, write_ros2_bag
from test_sources_data import make_frames, mean_abs_error

W, H = 128, 64


def test_a_turned_camera_shifted_by_its_yaw_sees_the_same_image():
    """Rendered views at one spot with three yaws: rolled by ``shift_from_yaw`` they agree
    (up to the renderer's sub-column resampling); as rendered they do not."""
    world = make_route("crossing", "indoor", 0).world
    yaws = [0.0, 1.0, -2.5]
    views = [render(world, 1.0, 0.3, yaw, 0.0, 256, 128) for yaw in yaws]
    shifted = [apply_shift(v, shift_from_yaw(256, yaw)) for v, yaw in zip(views, yaws)]
    for k in (1, 2):
        assert mean_abs_error(shifted[0], shifted[k]) < 0.25 * mean_abs_error(views[0], views[k])
        assert mean_abs_error(shifted[0], shifted[k]) < 12.0


def test_heading_conventions():
    for width in (7, 256, 5760):
        for heading in (0.0, 12.5, 90.0, 359.9, -45.0, 720.0):
            s = shift_from_heading(width, heading)
            assert 0 <= s < width
            assert s == shift_from_yaw(width, -math.radians(heading))
    # the image centre looking north: north is at the centre column, rolled to column 0
    assert shift_from_heading(360, 0.0) == 180
    # looking east: north is a quarter turn to the left of the centre
    assert shift_from_heading(360, 90.0) == 90
    for bad in (float("nan"), float("inf")):
        with pytest.raises(InputError):
            shift_from_heading(256, bad)


def test_headings_are_interpolated_on_the_circle_and_refused_with_gaps():
    t = np.array([0.0, 0.2, 0.4])
    yaw = np.radians([170.0, -170.0, -150.0])          # crosses +-180 between the samples
    got = headings_at(t, yaw, np.array([0.0, 0.1, 0.3]))
    assert np.allclose(got, [190.0, 180.0, 160.0])
    assert headings_at(t, yaw, np.array([0.0, 1.5])) is None       # a frame far past the end
    assert headings_at(np.array([0.0, 5.0]), yaw[:2], np.array([2.5])) is None   # a hole


def _turning_poses(n: int, fps: float = 10.0) -> Poses:
    t = 1700000000.0 + np.arange(n) / fps
    yaw = np.linspace(-3.0, 3.0, n)                      # more than one turn, wrapping at pi
    return Poses(t=t, x=np.linspace(0, 3, n), y=np.zeros(n), yaw=(yaw + np.pi) % (2 * np.pi) - np.pi)


@pytest.mark.parametrize("kind, pose_type", [("ros1", "odometry"), ("mcap", "posestamped")])
def test_bag_headings_come_from_its_pose_topic(tmp_path, kind, pose_type):
    frames = make_frames(6, W, H)
    poses = _turning_poses(30)
    stamps = poses.t[::5] + 0.05                          # between two pose samples
    if kind == "ros1":
        path = write_ros1_bag(tmp_path / "b.bag", frames, stamps, poses=poses, pose_type=pose_type)
    else:
        path = write_ros2_bag(tmp_path / "b", frames, stamps, storage="mcap", poses=poses,
                              pose_type=pose_type)
    with BagSource(path) as src:
        got = src.headings()
        assert "/odom" in src.heading_note
    want = -np.degrees(np.interp(stamps, poses.t, np.unwrap(poses.yaw)))
    diff = (got - want + 180.0) % 360.0 - 180.0
    assert np.all(np.abs(diff) < 1e-3)      # stamps are whole nanoseconds in the bag


def _imu_bag(path: Path, stamps, yaws, with_orientation: bool, extra_odom: bool = False) -> Path:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    frames = make_frames(len(stamps), W, H)
    with Writer(path) as w:
        cam = w.add_connection("/cam", "sensor_msgs/msg/Image", typestore=ts)
        imu = w.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=ts)
        odom = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts) if extra_odom else None
        for k, (t, yaw) in enumerate(zip(stamps, yaws)):
            ns = int(round(t * 1e9))
            hdr = T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](
                sec=ns // 10**9, nanosec=ns % 10**9), frame_id="imu")
            q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
            v = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
            cov = np.zeros(9)
            ocov = cov.copy()
            if not with_orientation:
                ocov[0] = -1.0                              # the driver's "no orientation"
            msg = T["sensor_msgs/msg/Imu"](header=hdr, orientation=q, orientation_covariance=ocov,
                                           angular_velocity=v, angular_velocity_covariance=cov,
                                           linear_acceleration=v, linear_acceleration_covariance=cov)
            w.write(imu, ns, ts.serialize_ros1(msg, "sensor_msgs/msg/Imu"))
            if odom is not None:
                pose = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                                     orientation=q), covariance=np.zeros(36))
                tw = T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=v, angular=v), covariance=np.zeros(36))
                w.write(odom, ns, ts.serialize_ros1(T["nav_msgs/msg/Odometry"](
                    header=hdr, child_frame_id="base", pose=pose, twist=tw), "nav_msgs/msg/Odometry"))
            img = T["sensor_msgs/msg/Image"](header=hdr, height=H, width=W, encoding="rgb8", is_bigendian=0,
                                             step=3 * W, data=frames[k].reshape(-1))
            w.write(cam, ns, ts.serialize_ros1(img, "sensor_msgs/msg/Image"))
    return path


def test_one_orientation_on_every_message_is_a_placeholder(tmp_path):
    """GPS-only odometry: positions change, the orientation is the identity quaternion throughout."""
    frames = make_frames(4, W, H)
    poses = Poses(t=100.0 + np.arange(20) * 0.1, x=np.linspace(0, 5, 20), y=np.zeros(20), yaw=np.zeros(20))
    path = write_ros1_bag(tmp_path / "gps.bag", frames, poses.t[::5], poses=poses)
    with BagSource(path) as src:
        assert src.headings() is None and "one orientation" in src.heading_note


def test_imu_orientation_is_used_unless_the_driver_says_it_has_none(tmp_path):
    stamps = 100.0 + np.arange(5) * 0.1
    yaws = np.radians([10.0, 20.0, 40.0, 80.0, 100.0])
    with BagSource(_imu_bag(tmp_path / "imu.bag", stamps, yaws, True)) as src:
        assert np.allclose(src.headings(), (-np.degrees(yaws)) % 360.0)
        assert "sensor_msgs/msg/Imu" in src.heading_note
    with BagSource(_imu_bag(tmp_path / "none.bag", stamps, yaws, False)) as src:
        assert src.headings() is None


def test_odometry_comes_before_imu_and_two_odometries_need_a_choice(tmp_path):
    stamps = 100.0 + np.arange(4) * 0.1
    yaws = np.radians([0.0, 30.0, 60.0, 90.0])
    path = _imu_bag(tmp_path / "two.bag", stamps, yaws, True, extra_odom=True)
    with BagSource(path) as src:
        assert np.allclose(src.headings(), (-np.degrees(yaws)) % 360.0)
        assert src.heading_note.startswith("/odom ")
    with BagSource(path, heading_topic="/imu/data") as src:
        assert np.allclose(src.headings(), (-np.degrees(yaws)) % 360.0)
        assert src.heading_note.startswith("/imu/data ")
    poses = _turning_poses(20)
    frames = make_frames(4, W, H)
    both = write_ros1_bag(tmp_path / "odoms.bag", frames, poses.t[::5], poses=poses, pose_topic="/odom")
    twice = _second_odometry(both, tmp_path / "odoms2.bag")
    with BagSource(twice) as src:
        assert src.headings() is None and "several orientation topics" in src.heading_note
    with BagSource(twice, heading_topic="/odometry/filtered") as src:
        assert src.headings() is not None
    with BagSource(path, heading_topic="/nope") as src:
        with pytest.raises(InputError) as err:
            src.headings()
        assert "/imu/data, /odom" in str(err.value) and "\n" not in str(err.value)


def _second_odometry(bag: Path, out: Path) -> Path:
    """``bag`` with its /odom messages written again on /odometry/filtered."""
    from rosbags.rosbag1 import Reader, Writer

    with Reader(bag) as reader, Writer(out) as writer:
        conns = {}
        for conn, t, raw in reader.messages():
            targets = [conn.topic] + (["/odometry/filtered"] if conn.topic == "/odom" else [])
            for topic in targets:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, conn.msgtype, msgdef=conn.msgdef.data,
                                                         md5sum=conn.digest)
                writer.write(conns[topic], t, raw)
    return out


def _photo(path: Path, rgb: np.ndarray, second: int, heading: float) -> None:
    exif = Image.Exif()
    exif[0x8769] = {0x9003: f"2024:05:01 10:00:{second:02d}"}
    exif[0x8825] = {16: "T", 17: TiffImagePlugin.IFDRational(round(heading * 100), 100)}
    Image.fromarray(rgb).save(path, quality=95, exif=exif)


def test_photo_folder_headings_from_exif_and_placeholders_ignored(tmp_path):
    frames = make_frames(3, W, H)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for k, (f, h) in enumerate(zip(frames, [350.0, 10.5, 2.25])):
        _photo(tmp_path / "a" / f"{k}.jpg", f, k, h)
        _photo(tmp_path / "b" / f"{k}.jpg", f, k, 0.0)     # the same heading on every photo
    with FolderSource(tmp_path / "a") as src:
        assert np.allclose(src.headings(), [350.0, 10.5, 2.25]) and "GPSImgDirection" in src.heading_note
    with FolderSource(tmp_path / "b") as src:
        assert src.headings() is None


def test_describe_shifts_by_the_recorded_heading(tmp_path):
    """A synthetic route written as a bag with its odometry: the stored shifts are the
    headings' shifts, and views of one spot from opposite directions come out aligned."""
    from engine.pipeline import DescribeSettings, describe_source

    world = make_route("crossing", "indoor", 0).world
    yaws = np.array([0.3, 0.3 + np.pi, -1.2])            # one spot, three headings
    t = 50.0 + np.arange(3, dtype=np.float64)
    views = [render(world, 1.0, 0.3, yaw, 0.0, 256, 128) for yaw in yaws]
    poses = Poses(t=t, x=np.ones(3), y=np.full(3, 0.3), yaw=yaws)
    path = write_ros1_bag(tmp_path / "spot.bag", views, t, poses=poses)
    settings = DescribeSettings(interval=0.5, options={"input_height": 64, "batch_size": 4})
    with BagSource(path) as src:
        descs = describe_source(src, settings, _model(settings), str(path))
    assert descs.meta["shift_from"] == "heading" and "/odom" in descs.meta["heading_note"]
    assert descs.shifts.tolist() == [shift_from_yaw(256, y) for y in yaws]
    shifted = [apply_shift(v, s) for v, s in zip(views, descs.shifts)]
    assert mean_abs_error(shifted[0], shifted[1]) < 12.0 and mean_abs_error(shifted[0], shifted[2]) < 12.0
    assert descs.vectors[0] @ descs.vectors[1] > 0.9


def _model(settings):
    from engine.descriptors import get

    return get(settings.descriptor, **settings.options)
