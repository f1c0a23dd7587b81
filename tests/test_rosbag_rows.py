"""ROS images with padded rows, compressed ROS1 chunks, truncated bags (issue 16, findings
12 and 13). Real bags written with rosbags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError
from engine.sources import BagSource
from engine.sources.rosbag import message_to_rgb
from test_sources_data import make_frames

W, H = 64, 32
PAD = 24      # bytes of padding after every row (drivers align rows, e.g. to 64 bytes)


def _pixels(rgb: np.ndarray, encoding: str) -> np.ndarray:
    """The pixel rows of ``encoding`` made from an RGB frame (uint8 view, one row per line)."""
    if encoding == "rgb8":
        data = rgb
    elif encoding == "bgr8":
        data = rgb[:, :, ::-1]
    else:  # mono16 / 16UC1, little endian
        grey = (rgb.astype(np.uint32).sum(axis=2) // 3).astype("<u2") * np.uint16(257)
        data = grey
    data = np.ascontiguousarray(data)
    return data.view(np.uint8).reshape(data.shape[0], -1)


def _image(typestore, rgb: np.ndarray, encoding: str, t: float, pad: int, ros1: bool, step=None):
    rows = _pixels(rgb, encoding)
    padded = np.concatenate([rows, np.full((rows.shape[0], pad), 0xAB, np.uint8)], axis=1)
    ns = int(round(t * 1e9))
    types = typestore.types
    stamp = types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    header = types["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), stamp=stamp, frame_id="cam")
    return types["sensor_msgs/msg/Image"](
        header=header, height=rgb.shape[0], width=rgb.shape[1], encoding=encoding, is_bigendian=0,
        step=padded.shape[1] if step is None else step, data=padded.reshape(-1))


def _write(path: Path, kind: str, msgs: list, compression=None) -> Path:
    from rosbags.typesys import Stores, get_typestore

    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        ts = get_typestore(Stores.ROS1_NOETIC)
        writer = Writer(path)
        if compression:
            writer.set_compression(getattr(Writer.CompressionFormat, compression))
        serialize = ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        ts = get_typestore(Stores.ROS2_HUMBLE)
        writer = Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3 if kind == "sqlite3"
                        else StoragePlugin.MCAP)
        serialize = ts.serialize_cdr
    with writer:
        conn = writer.add_connection("/cam/image_raw", "sensor_msgs/msg/Image", typestore=ts)
        for t, build in msgs:
            msg = build(ts)
            writer.write(conn, int(round(t * 1e9)), serialize(msg, "sensor_msgs/msg/Image"))
    return path


def _frames_of(path: Path) -> list[np.ndarray]:
    with BagSource(path) as src:
        return [src.frame_at(i).rgb for i in range(src.frame_count)]


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "mono16", "16UC1"])
def test_padded_rows_decode_exactly_like_unpadded_ones(tmp_path, kind, encoding):
    frames = make_frames(3, W, H)
    ros1 = kind == "ros1"
    name = "p.bag" if ros1 else "p"
    padded = _write(tmp_path / name, kind, [
        (1.0 + k, lambda ts, f=f: _image(ts, f, encoding, 1.0, PAD, ros1)) for k, f in enumerate(frames)])
    plain = _write(tmp_path / ("u" + name), kind, [
        (1.0 + k, lambda ts, f=f: _image(ts, f, encoding, 1.0, 0, ros1)) for k, f in enumerate(frames)])
    got, want = _frames_of(padded), _frames_of(plain)
    for g, w, f in zip(got, want, frames):
        assert np.array_equal(g, w)
        if encoding in ("rgb8", "bgr8"):
            assert np.array_equal(g, f)   # rgb8 / bgr8: the very pixels written


def test_a_step_shorter_than_a_row_is_refused_in_one_line(tmp_path):
    frame = make_frames(1, W, H)[0]
    bag = _write(tmp_path / "short.bag", "ros1", [
        (1.0, lambda ts: _image(ts, frame, "rgb8", 1.0, 0, True, step=3 * W - 6))])
    with pytest.raises(InputError) as err:
        _frames_of(bag)
    assert "step" in str(err.value) and "\n" not in str(err.value)


def test_unpadding_keeps_the_message_otherwise_intact():
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    frame = make_frames(1, W, H)[0]
    assert np.array_equal(message_to_rgb(_image(ts, frame, "rgb8", 1.0, PAD, False), "sensor_msgs/msg/Image"),
                          frame)


@pytest.mark.parametrize("compression", ["BZ2", "LZ4"])
def test_ros1_compressed_chunks_read(tmp_path, compression):
    frames = make_frames(4, W, H)
    bag = _write(tmp_path / "c.bag", "ros1", [
        (1.0 + k, lambda ts, f=f: _image(ts, f, "rgb8", 1.0, 0, True)) for k, f in enumerate(frames)],
        compression=compression)
    for got, want in zip(_frames_of(bag), frames):
        assert np.array_equal(got, want)


def test_ros1_type_names_are_stored_short_and_read_long(tmp_path):
    """A ROS1 bag names the type 'sensor_msgs/Image'; ROS2 'sensor_msgs/msg/Image'."""
    frame = make_frames(1, W, H)[0]
    bag = _write(tmp_path / "t.bag", "ros1", [(1.0, lambda ts: _image(ts, frame, "rgb8", 1.0, 0, True))])
    assert b"type=sensor_msgs/Image" in bag.read_bytes()
    assert np.array_equal(_frames_of(bag)[0], frame)


@pytest.mark.parametrize("kind, hint", [("ros1", "rosbag reindex"), ("mcap", "mcap recover")])
def test_a_truncated_bag_says_how_to_recover_it(tmp_path, kind, hint):
    frames = make_frames(6, W, H)
    path = _write(tmp_path / ("cut.bag" if kind == "ros1" else "cut"), kind, [
        (1.0 + k, lambda ts, f=f: _image(ts, f, "rgb8", 1.0, 0, kind == "ros1")) for k, f in enumerate(frames)])
    file = path if kind == "ros1" else next(path.glob("*.mcap"))
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])          # the recorder was killed mid-write
    if kind != "ros1":
        (path / "metadata.yaml").unlink()
    with pytest.raises(InputError) as err:
        _frames_of(path)
    assert hint in str(err.value) and "\n" not in str(err.value)
