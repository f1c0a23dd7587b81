"""The recording writers, checked with the libraries directly (not with panotopo's readers)."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from engine.errors import InputError
from engine.poses import Poses
from engine.synth.writers import (
    write_image_folder,
    write_poses_csv,
    write_ros1_bag,
    write_ros2_bag,
    write_video,
)
from test_sources_data import make_frames, make_stamps, mean_abs_error


def read_bag(path: Path) -> dict[str, list]:
    """topic -> [(msgtype, log time ns, message)] read with rosbags."""
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append(
                (conn.msgtype, t, reader.deserialize(raw, conn.msgtype)))
    return out


# FFmpeg reports MPEG-4 part 2 in .mp4 as "FMP4"; it is the codec written as "mp4v".
@pytest.mark.parametrize("suffix,fourccs", [(".mp4", {"mp4v", "fmp4"}), (".avi", {"mjpg"})])
def test_write_video_opencv_reads_it_back(tmp_path, suffix, fourccs):
    frames = make_frames(12)
    path = write_video(tmp_path / f"v{suffix}", frames, fps=10.0)
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    assert "".join(chr((code >> 8 * i) & 0xFF) for i in range(4)).lower() in fourccs
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(10.0)
    decoded = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        decoded.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    cap.release()
    assert len(decoded) == len(frames)
    for a, b in zip(decoded, frames):
        assert a.shape == b.shape
        assert mean_abs_error(a, b) < 6.0


def test_write_video_bad_target(tmp_path):
    with pytest.raises(InputError, match="mp4 or .avi"):
        write_video(tmp_path / "v.gif", make_frames(2), fps=10)
    (tmp_path / "dir.mp4").mkdir()
    with pytest.raises(InputError, match="cannot open a video writer"):
        write_video(tmp_path / "dir.mp4", make_frames(2), fps=10)


def test_write_image_folder(tmp_path):
    frames = make_frames(5)
    stamps = make_stamps(5, start=12.25)
    folder = write_image_folder(tmp_path / "imgs", frames, stamps)
    names = sorted(p.name for p in folder.glob("*.png"))
    assert names == [f"frame_{k:06d}.png" for k in range(5)]
    for k, name in enumerate(names):
        rgb = cv2.cvtColor(cv2.imread(str(folder / name)), cv2.COLOR_BGR2RGB)
        assert np.array_equal(rgb, frames[k])
    lines = (folder / "stamps.csv").read_text().splitlines()
    assert lines[0] == "filename,stamp"
    rows = [line.split(",") for line in lines[1:]]
    assert [r[0] for r in rows] == names
    assert np.array_equal([float(r[1]) for r in rows], stamps)


def test_write_poses_csv(tmp_path):
    poses = Poses(t=np.array([0.0, 0.5]), x=np.array([1.0, 2.5]), y=np.array([-1.0, 0.25]),
                  yaw=np.array([0.1, -3.0]))
    lines = write_poses_csv(tmp_path / "p.csv", poses).read_text().splitlines()
    assert lines == ["t,x,y,yaw", "0.0,1.0,-1.0,0.1", "0.5,2.5,0.25,-3.0"]
    no_yaw = Poses(t=poses.t, x=poses.x, y=poses.y)
    assert write_poses_csv(tmp_path / "q.csv", no_yaw).read_text().splitlines()[0] == "t,x,y"


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_bag_writers_messages(tmp_path, kind):
    frames = make_frames(4)
    stamps = make_stamps(4, start=1700000000.5)
    poses = Poses(t=stamps, x=np.arange(4.0), y=-np.arange(4.0), yaw=np.array([0, 1, 2, 3.0]))
    if kind == "ros1":
        path = write_ros1_bag(tmp_path / "a.bag", frames, stamps, poses=poses)
    else:
        path = write_ros2_bag(tmp_path / "a", frames, stamps, storage=kind, poses=poses)
        assert (path / "metadata.yaml").exists()
    topics = read_bag(path)
    assert set(topics) == {"/camera/image_raw", "/odom"}
    images = topics["/camera/image_raw"]
    assert [m[0] for m in images] == ["sensor_msgs/msg/Image"] * 4
    for (_, t, msg), rgb, stamp in zip(images, frames, stamps):
        assert t == round(stamp * 1e9)
        assert msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 == pytest.approx(stamp)
        assert (msg.encoding, msg.height, msg.width, msg.step) == ("rgb8", 64, 128, 384)
        assert np.array_equal(np.asarray(msg.data).reshape(64, 128, 3), rgb)
    odom = topics["/odom"]
    assert [m[0] for m in odom] == ["nav_msgs/msg/Odometry"] * 4
    for k, (_, _, msg) in enumerate(odom):
        p = msg.pose.pose
        assert (p.position.x, p.position.y) == (k, -k)
        assert 2 * math.atan2(p.orientation.z, p.orientation.w) == pytest.approx(k)


def test_bag_writer_encodings(tmp_path):
    rgb = make_frames(1)[0]
    msgs = {}
    for enc in ["bgr8", "mono8", "mono16", "bayer_rggb8"]:
        path = write_ros1_bag(tmp_path / f"{enc}.bag", [rgb], [1.0], encoding=enc)
        msgs[enc] = read_bag(path)["/camera/image_raw"][0][2]
        assert msgs[enc].encoding == enc
    assert np.array_equal(np.asarray(msgs["bgr8"].data).reshape(64, 128, 3), rgb[:, :, ::-1])
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    assert np.array_equal(np.asarray(msgs["mono8"].data).reshape(64, 128), gray)
    mono16 = np.frombuffer(np.asarray(msgs["mono16"].data).tobytes(), "<u2").reshape(64, 128)
    assert msgs["mono16"].step == 256
    assert np.array_equal(mono16, gray.astype(np.uint16) * 257)
    bayer = np.asarray(msgs["bayer_rggb8"].data).reshape(64, 128)
    assert np.array_equal(bayer[0::2, 0::2], rgb[0::2, 0::2, 0])  # R
    assert np.array_equal(bayer[0::2, 1::2], rgb[0::2, 1::2, 1])  # G
    assert np.array_equal(bayer[1::2, 0::2], rgb[1::2, 0::2, 1])  # G
    assert np.array_equal(bayer[1::2, 1::2], rgb[1::2, 1::2, 2])  # B
    with pytest.raises(InputError, match="yuv422"):
        write_ros1_bag(tmp_path / "x.bag", [rgb], [1.0], encoding="yuv422")


@pytest.mark.parametrize("fmt", ["jpeg", "png"])
def test_bag_writer_compressed_and_pose_stamped(tmp_path, fmt):
    frames = make_frames(3)
    stamps = make_stamps(3)
    poses = Poses(t=stamps, x=np.ones(3), y=np.zeros(3), yaw=np.array([0.5, 0.6, 0.7]))
    path = write_ros2_bag(tmp_path / "c", frames, stamps, storage="mcap", compressed=True,
                          image_format=fmt, poses=poses, pose_topic="/gt",
                          pose_type="posestamped")
    topics = read_bag(path)
    for (msgtype, _, msg), rgb in zip(topics["/camera/image_raw"], frames):
        assert msgtype == "sensor_msgs/msg/CompressedImage"
        assert msg.format == fmt
        decoded = cv2.cvtColor(cv2.imdecode(np.asarray(msg.data), cv2.IMREAD_COLOR),
                               cv2.COLOR_BGR2RGB)
        err = mean_abs_error(decoded, rgb)
        assert err == 0.0 if fmt == "png" else err < 3.0
    gt = topics["/gt"]
    assert [m[0] for m in gt] == ["geometry_msgs/msg/PoseStamped"] * 3
    assert 2 * math.atan2(gt[2][2].pose.orientation.z, gt[2][2].pose.orientation.w) == \
        pytest.approx(0.7)


def test_bag_writer_replaces_existing_and_checks_lengths(tmp_path):
    frames = make_frames(2)
    write_ros2_bag(tmp_path / "b", frames, [0.0, 0.1])
    write_ros2_bag(tmp_path / "b", frames[:1], [0.0])  # rosbags refuses; we replace
    assert len(read_bag(tmp_path / "b")["/camera/image_raw"]) == 1
    with pytest.raises(InputError, match="2 frames but 3 stamps"):
        write_ros1_bag(tmp_path / "c.bag", frames, [0.0, 0.1, 0.2])
    with pytest.raises(InputError, match="storage"):
        write_ros2_bag(tmp_path / "d", frames, [0.0, 0.1], storage="zip")
