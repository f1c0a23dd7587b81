"""Bags written the way other tools write them (issue 44 item 5).

- MCAP files of profile ``ros1`` (``mcap convert`` of a .bag, the ``mcap`` ROS1 writers):
  schema ``sensor_msgs/Image`` in ``ros1msg``, ROS1-serialised messages, chunks compressed
  with zstd, lz4 or not at all; written here with the ``mcap`` library's own writer.
- ROS2 bags recorded with ``--compression-mode message`` / ``file`` (rosbags' writer does
  what ``ros2 bag record`` does: zstd per message, or the whole storage file), opened as a
  directory and as the bare storage file without its metadata.yaml.
- ``16UC1`` and ``8UC1`` images (OpenCV-style names for mono16 / mono8).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError
from engine.sources import BagSource, list_image_topics, list_pose_topics, open_recording, read_poses
from engine.sources.bag_reader import normalize_type
from test_sources_data import make_frames

W, H = 64, 32
T0 = 1_700_000_000


def _stores():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC), get_typestore(Stores.ROS2_HUMBLE)


def _header(ts, ns: int, ros1: bool):
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return T["std_msgs/msg/Header"](**({"seq": 7} if ros1 else {}), stamp=stamp, frame_id="cam")


def _image(ts, data: np.ndarray, encoding: str, ns: int, ros1: bool, bigendian: int = 0):
    rows = np.ascontiguousarray(data).view(np.uint8).reshape(data.shape[0], -1)
    return ts.types["sensor_msgs/msg/Image"](
        header=_header(ts, ns, ros1), height=data.shape[0], width=data.shape[1], encoding=encoding,
        is_bigendian=bigendian, step=rows.shape[1], data=rows.reshape(-1))


def _odometry(ts, ns: int, x: float, yaw: float, ros1: bool):
    T = ts.types
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=2.0 * x, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2)))
    cov = np.zeros(36)
    return T["nav_msgs/msg/Odometry"](
        header=_header(ts, ns, ros1), child_frame_id="base",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                               angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
            covariance=cov))


def write_mcap(path: Path, profile: str, compression: str, messages, short_names: bool = True) -> Path:
    """An MCAP written with the ``mcap`` library, as its ROS1 writer does for ``profile='ros1'``:
    one ``ros1msg`` schema per type (named ``pkg/Type``), channels in ``ros1`` encoding.
    ``profile='ros2'`` / ``''`` writes ``ros2msg`` schemas and ``cdr`` channels.
    ``messages``: (topic, msgtype pkg/msg/Type, log ns, message object)."""
    from mcap.writer import CompressionType, Writer

    ts1, ts2 = _stores()
    ros1 = profile == "ros1"
    ts = ts1 if ros1 else ts2
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=getattr(CompressionType, compression.upper()))
        writer.start(profile=profile, library="panotopo-test")
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for topic, msgtype, ns, msg in messages:
            if msgtype not in schemas:
                if ros1:
                    text = ts.generate_msgdef(msgtype)[0]
                else:
                    text = ts.generate_msgdef(msgtype, ros_version=2)[0]
                name = msgtype.replace("/msg/", "/") if short_names else msgtype
                schemas[msgtype] = writer.register_schema(
                    name=name, encoding="ros1msg" if ros1 else "ros2msg", data=text.encode())
            if topic not in channels:
                channels[topic] = writer.register_channel(
                    topic=topic, message_encoding="ros1" if ros1 else "cdr", schema_id=schemas[msgtype])
            data = ts.serialize_ros1(msg, msgtype) if ros1 else ts.serialize_cdr(msg, msgtype)
            writer.add_message(channels[topic], log_time=ns, data=bytes(data), publish_time=ns)
        writer.finish()
    return path


def _frames_of(path: Path) -> list[np.ndarray]:
    with BagSource(path) as src:
        return [src.frame_at(i).rgb for i in range(src.frame_count)]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_ros1_profile_mcap_reads_images_stamps_and_odometry(tmp_path, compression):
    ts1, _ = _stores()
    frames = make_frames(4, W, H)
    stamps = [T0 * 10**9 + k * 250_000_000 for k in range(4)]
    msgs = [("/cam/image_raw", "sensor_msgs/msg/Image", ns + 5_000_000, _image(ts1, f, "rgb8", ns, True))
            for f, ns in zip(frames, stamps)]
    msgs += [("/odom", "nav_msgs/msg/Odometry", ns + 1, _odometry(ts1, ns, 0.5 * k, 0.3 * k, True))
             for k, ns in enumerate(stamps)]
    path = write_mcap(tmp_path / "r1.mcap", "ros1", compression, msgs)
    assert list_image_topics(path) == [("/cam/image_raw", "sensor_msgs/msg/Image", 4)]
    assert list_pose_topics(path) == [("/odom", "nav_msgs/msg/Odometry", 4)]
    with open_recording(path) as src:
        # header stamps, not the log times 5 ms later
        assert np.allclose(src.stamps(), np.array(stamps) * 1e-9, atol=1e-6)
        for k, f in enumerate(frames):
            assert np.array_equal(src.frame_at(k).rgb, f)
        assert [g.index for g in src.frames(0.0)] == [0, 1, 2, 3]
    poses = read_poses(path)
    assert np.allclose(poses.x, 0.5 * np.arange(4)) and np.allclose(poses.yaw, 0.3 * np.arange(4))


@pytest.mark.parametrize("profile, compression, short", [
    ("ros2", "zstd", False), ("ros2", "lz4", False), ("ros2", "zstd", True), ("", "zstd", True)])
def test_cdr_mcap_from_the_mcap_writer(tmp_path, profile, compression, short):
    """ros2 profile (rosbags' reader) and no profile (the mcap reader); type names spelled
    sensor_msgs/msg/Image or sensor_msgs/Image."""
    _, ts2 = _stores()
    frames = make_frames(3, W, H)
    msgs = [("/cam", "sensor_msgs/msg/Image", T0 * 10**9 + k, _image(ts2, f, "rgb8", T0 * 10**9 + k, False))
            for k, f in enumerate(frames)]
    path = write_mcap(tmp_path / "r2.mcap", profile, compression, msgs, short_names=short)
    assert [m for _, m, _ in list_image_topics(path)] == ["sensor_msgs/msg/Image"]
    for got, want in zip(_frames_of(path), frames):
        assert np.array_equal(got, want)


def _ros2_bag(path: Path, storage: str, mode: str, frames) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    _, ts2 = _stores()
    writer = Writer(path, version=9, storage_plugin=getattr(StoragePlugin, storage.upper()))
    writer.set_compression(getattr(CompressionMode, mode.upper()), CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/cam", "sensor_msgs/msg/Image", typestore=ts2)
        for k, f in enumerate(frames):
            ns = T0 * 10**9 + k * 100_000_000
            writer.write(conn, ns, ts2.serialize_cdr(_image(ts2, f, "rgb8", ns, False), "sensor_msgs/msg/Image"))
    return path


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_message_compressed_ros2_bag_with_and_without_its_metadata(tmp_path, storage):
    frames = make_frames(3, W, H)
    bag = _ros2_bag(tmp_path / "m", storage, "message", frames)
    (bare,) = [p for p in bag.iterdir() if p.suffix in (".mcap", ".db3")]
    alone = tmp_path / "alone"
    alone.mkdir()
    moved = alone / bare.name
    moved.write_bytes(bare.read_bytes())  # the storage file without metadata.yaml
    for path in (bag, moved, alone):
        for got, want in zip(_frames_of(path), frames):
            assert np.array_equal(got, want)


def test_file_compressed_ros2_bag_reads_as_a_directory_and_says_what_to_do_alone(tmp_path):
    frames = make_frames(3, W, H)
    bag = _ros2_bag(tmp_path / "f", "mcap", "file", frames)
    for got, want in zip(_frames_of(bag), frames):
        assert np.array_equal(got, want)
    (packed,) = bag.glob("*.zstd")
    for alone in (packed, bag):
        if alone == bag:
            (bag / "metadata.yaml").unlink()       # the directory without its metadata
        with pytest.raises(InputError) as err:
            open_recording(alone)
        text = str(err.value)
        assert "zstd -d" in text and "\n" not in text


@pytest.mark.parametrize("kind", ["ros1", "mcap-ros1", "ros2"])
def test_16uc1_and_8uc1_read_as_mono16_and_mono8(tmp_path, kind):
    ts1, ts2 = _stores()
    ts = ts2 if kind == "ros2" else ts1
    ros1 = kind != "ros2"
    rng = np.random.default_rng(3)
    grey16 = rng.integers(0, 65536, size=(H, W)).astype("<u2")
    grey16[0, :4] = [0, 257, 65535, 65279]
    grey8 = rng.integers(0, 256, size=(H, W)).astype(np.uint8)
    cases = [("16UC1", grey16), ("mono16", grey16), ("8UC1", grey8), ("mono8", grey8)]
    got = {}
    for k, (encoding, data) in enumerate(cases):
        ns = T0 * 10**9 + k
        msg = _image(ts, data, encoding, ns, ros1)
        if kind == "ros1":
            from rosbags.rosbag1 import Writer

            path = tmp_path / f"{encoding}.bag"
            with Writer(path) as w:
                c = w.add_connection("/depth", "sensor_msgs/msg/Image", typestore=ts)
                w.write(c, ns, ts.serialize_ros1(msg, "sensor_msgs/msg/Image"))
        elif kind == "mcap-ros1":
            path = write_mcap(tmp_path / f"{encoding}.mcap", "ros1", "zstd",
                              [("/depth", "sensor_msgs/msg/Image", ns, msg)])
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            path = tmp_path / encoding
            with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
                c = w.add_connection("/depth", "sensor_msgs/msg/Image", typestore=ts)
                w.write(c, ns, ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))
        (got[encoding],) = _frames_of(path)
    assert np.array_equal(got["16UC1"], got["mono16"])
    assert np.array_equal(got["8UC1"], got["mono8"])
    rgb = got["16UC1"]
    assert np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2])
    # the documented scaling: linear over the full 16-bit range, 0 -> 0, 65535 -> 255
    assert rgb[0, :3, 0].tolist() == [0, 1, 255]
    order = np.argsort(grey16.reshape(-1), kind="stable")
    assert np.all(np.diff(rgb[..., 0].reshape(-1)[order].astype(int)) >= 0)   # monotonic
    assert np.array_equal(got["8UC1"][..., 0], grey8)


def test_type_names_normalise_either_spelling():
    assert normalize_type("sensor_msgs/Image") == "sensor_msgs/msg/Image"
    assert normalize_type("sensor_msgs/msg/Image") == "sensor_msgs/msg/Image"
    assert normalize_type("nav_msgs/Odometry") == "nav_msgs/msg/Odometry"
    assert normalize_type("geometry_msgs/msg/PoseStamped") == "geometry_msgs/msg/PoseStamped"


def test_an_mcap_of_another_encoding_is_refused_in_one_line(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "json.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="test")
        sid = w.register_schema(name="Thing", encoding="jsonschema", data=b"{}")
        cid = w.register_channel(topic="/thing", message_encoding="json", schema_id=sid)
        w.add_message(cid, log_time=1, data=b"{}", publish_time=1)
        w.finish()
    with pytest.raises(InputError) as err:
        open_recording(path)
    assert "json" in str(err.value) and "\n" not in str(err.value)


def test_an_unreadable_encoding_is_refused_in_one_line_that_says_what_to_do(tmp_path):
    from rosbags.rosbag1 import Writer

    ts1, _ = _stores()
    depth = np.linspace(0.5, 9.0, H * W, dtype="<f4").reshape(H, W)   # metres
    path = tmp_path / "depth.bag"
    with Writer(path) as w:
        c = w.add_connection("/depth", "sensor_msgs/msg/Image", typestore=ts1)
        w.write(c, 1, ts1.serialize_ros1(_image(ts1, depth, "32FC1", 1, True), "sensor_msgs/msg/Image"))
    with pytest.raises(InputError) as err:
        open_recording(path)
    text = str(err.value)
    assert "32FC1" in text and "convert" in text and "\n" not in text
