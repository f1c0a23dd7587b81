"""Frame sources on real files: videos, image folders, ROS1/ROS2 bags, poses."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.frames import sample_indices
from engine.sources import open_source
from engine.poses import Poses
from engine.sources import (
    BagSource,
    FolderSource,
    VideoSource,
    list_image_topics,
    list_pose_topics,
    open_recording,
    read_poses,
)
from engine.synth.writers import (
    write_image_folder,
    write_poses_csv,
    write_ros1_bag,
    write_ros2_bag,
    write_video,
)
from test_sources_data import (
    make_frames,
    make_stamps,
    mean_abs_error,
    ros1_compressed,
    ros1_image,
    write_messages_bag,
)

N = 35          # frames per recording: 3.4 s at 10 fps
FPS = 10.0
VIDEO_MAE = 6.0  # mp4v / MJPG at 128x64 measure 2.5..4.5; distinct frames differ by > 15
JPEG_MAE = 3.0


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    return make_frames(N)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory, frames) -> dict[str, Path]:
    """The same frames in every format; bags on ROS time 1700000000.25 + k / FPS."""
    d = tmp_path_factory.mktemp("rec")
    stamps = make_stamps(N, FPS, start=1700000000.25)
    return {
        "mp4": write_video(d / "v.mp4", frames, FPS),
        "avi": write_video(d / "v.avi", frames, FPS),
        "folder": write_image_folder(d / "imgs", frames, stamps),
        "ros1": write_ros1_bag(d / "r1.bag", frames, stamps),
        "sqlite3": write_ros2_bag(d / "r2s", frames, stamps, storage="sqlite3"),
        "mcap": write_ros2_bag(d / "r2m", frames, stamps, storage="mcap"),
    }


def sampled(source, interval: float) -> tuple[list[int], list[float], list[np.ndarray]]:
    got = list(source.frames(interval))
    return [f.index for f in got], [f.stamp for f in got], [f.rgb for f in got]


# --- video ----------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["mp4", "avi"])
def test_video_counts_stamps_pixels(recordings, frames, kind):
    with open_recording(recordings[kind]) as src:
        assert isinstance(src, VideoSource)
        assert src.frame_count == N
        assert src.resolution == (128, 64)
        assert np.allclose(src.stamps(), np.arange(N) / FPS, atol=1e-6)
        assert src.duration == pytest.approx((N - 1) / FPS)
        for i in [0, 1, 17, N - 1]:
            f = src.frame_at(i)
            assert (f.index, f.rgb.dtype, f.rgb.shape) == (i, np.uint8, (64, 128, 3))
            assert f.stamp == pytest.approx(i / FPS)
            assert mean_abs_error(f.rgb, frames[i]) < VIDEO_MAE
            # and it is this frame, not a neighbour
            assert mean_abs_error(f.rgb, frames[(i + 1) % N]) > 2 * VIDEO_MAE


def test_video_sampling_single_pass_matches_random_access(recordings):
    src = VideoSource(recordings["mp4"])
    # frames() before the stamps are known: one pass that also fills the stamp cache
    idx, stamps, rgbs = sampled(src, 1.0)
    assert idx == [0, 10, 20, 30]
    assert stamps == pytest.approx([0.0, 1.0, 2.0, 3.0])
    assert src._stamps is not None
    assert idx == list(src.sample_indices(1.0))
    # frames() again with known stamps, and random access (seek back and forth)
    idx2, _, rgbs2 = sampled(src, 1.0)
    assert idx2 == idx
    for i, a, b in zip(idx, rgbs, rgbs2):
        assert np.array_equal(a, b)
    for i, a in reversed(list(zip(idx, rgbs))):
        assert np.array_equal(src.frame_at(i).rgb, a)
    assert np.array_equal(src.frame_at(3).rgb, src.frame_at(3).rgb)
    assert sampled(src, 0.0)[0] == list(range(N))
    assert sampled(src, 0.25)[0] == list(sample_indices(np.arange(N) / FPS, 0.25))
    src.close()


# --- folder ---------------------------------------------------------------------


def test_folder_lossless_with_stamps_csv(recordings, frames):
    with open_recording(recordings["folder"]) as src:
        assert isinstance(src, FolderSource)
        assert src.frame_count == N
        assert np.allclose(src.stamps(), make_stamps(N, FPS, start=1700000000.25), atol=1e-6)
        for i in [0, 9, N - 1]:
            assert np.array_equal(src.frame_at(i).rgb, frames[i])
        assert sampled(src, 1.0)[0] == [0, 10, 20, 30]


def test_folder_natural_order_and_stamp_forms(tmp_path, frames):
    names = ["img1.png", "img2.png", "img10.png", "img9.jpg"]  # natural: 1, 2, 9, 10
    for name, rgb in zip(names, frames):
        cv2.imwrite(str(tmp_path / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    (tmp_path / "notes.txt").write_text("not an image")
    src = FolderSource(tmp_path, interval=0.5)
    assert [p.name for p in src.files] == ["img1.png", "img2.png", "img9.jpg", "img10.png"]
    assert np.array_equal(src.stamps(), [0.0, 0.5, 1.0, 1.5])
    assert np.array_equal(src.frame_at(3).rgb, frames[2])
    assert mean_abs_error(src.frame_at(2).rgb, frames[3]) < JPEG_MAE
    (tmp_path / "stamps.csv").write_text("3.0\n3.5\n\n4.25\n5.0\n")
    assert np.array_equal(FolderSource(tmp_path).stamps(), [3.0, 3.5, 4.25, 5.0])
    (tmp_path / "stamps.csv").write_text(
        "filename,stamp\nimg10.png,9\nimg1.png,1\nimg9.jpg,8.5\nimg2.png,2\n")
    assert np.array_equal(open_recording(tmp_path).stamps(), [1.0, 2.0, 8.5, 9.0])


# --- bags -----------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_bag_raw_rgb_lossless(recordings, frames, kind):
    with open_recording(recordings[kind]) as src:
        assert isinstance(src, BagSource)
        assert src.topic == "/camera/image_raw"
        assert src.frame_count == N
        assert src.resolution == (128, 64)
        assert np.allclose(src.stamps(), make_stamps(N, FPS, start=1700000000.25), atol=1e-6)
        for i in [0, 13, N - 1, 2]:
            f = src.frame_at(i)
            assert f.index == i and np.array_equal(f.rgb, frames[i])
        idx, stamps, rgbs = sampled(src, 1.0)
        assert idx == [0, 10, 20, 30]
        assert np.allclose(stamps, src.stamps()[idx])
        for i, rgb in zip(idx, rgbs):
            assert np.array_equal(rgb, frames[i])


def test_ros2_bare_storage_files_and_directory_without_metadata(recordings, frames, tmp_path):
    for kind, suffix in [("sqlite3", ".db3"), ("mcap", ".mcap")]:
        bare = next(recordings[kind].glob(f"*{suffix}"))
        with open_source(bare) as src:
            assert src.frame_count == N
            assert np.array_equal(src.frame_at(5).rgb, frames[5])
        lone = tmp_path / f"lone_{kind}"
        lone.mkdir()
        (lone / bare.name).write_bytes(bare.read_bytes())
        with open_recording(lone) as src:
            assert isinstance(src, BagSource) and src.frame_count == N


@pytest.mark.parametrize("encoding,max_err", [
    ("bgr8", 0.0), ("mono8", 0.0), ("mono16", 1.0), ("bayer_rggb8", 3.0)])
def test_bag_encodings(tmp_path, frames, encoding, max_err):
    few = frames[:4]
    path = write_ros1_bag(tmp_path / "e.bag", few, make_stamps(4), encoding=encoding)
    with BagSource(path) as src:
        for i, rgb in enumerate(few):
            got = src.frame_at(i).rgb
            want = rgb
            if encoding.startswith("mono"):
                want = np.repeat(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)[:, :, None], 3, axis=2)
                assert np.array_equal(got[:, :, 0], got[:, :, 2])
            if max_err == 0.0:
                assert np.array_equal(got, want)
            elif encoding == "mono16":
                assert np.abs(got.astype(int) - want).max() <= 1
            else:
                # demosaicing blurs a little (measured 0.9); R/B swapped would be ~30
                assert mean_abs_error(got, want) < max_err
                assert mean_abs_error(got[:, :, ::-1], want) > 4 * max_err


@pytest.mark.parametrize("fmt,max_err", [("jpeg", JPEG_MAE), ("png", 0.0)])
def test_bag_compressed(tmp_path, frames, fmt, max_err):
    few = frames[:6]
    path = write_ros2_bag(tmp_path / "c", few, make_stamps(6), storage="mcap", compressed=True,
                          image_format=fmt)
    with open_recording(path) as src:
        for i, rgb in enumerate(few):
            assert mean_abs_error(src.frame_at(i).rgb, rgb) <= max_err


def test_grey_compressed_image(tmp_path, frames):
    gray = cv2.cvtColor(frames[0], cv2.COLOR_RGB2GRAY)
    png = cv2.imencode(".png", gray)[1].tobytes()
    path = write_messages_bag(tmp_path / "g.bag", [("/cam", 1.0, ros1_compressed(png, 1.0))])
    rgb = BagSource(path).frame_at(0).rgb
    assert rgb.shape == (64, 128, 3) and np.array_equal(rgb[:, :, 1], gray)


def test_two_image_topics_choice_and_listing(tmp_path, frames):
    msgs = [("/front", 1.0 + 0.1 * k, ros1_image(frames[k], 1.0 + 0.1 * k)) for k in range(5)]
    msgs += [("/back", 1.05 + 0.1 * k, ros1_image(frames[10 + k], 1.05 + 0.1 * k))
             for k in range(3)]
    msgs.sort(key=lambda m: m[1])
    path = write_messages_bag(tmp_path / "two.bag", msgs)
    assert list_image_topics(path) == [("/back", "sensor_msgs/msg/Image", 3),
                                       ("/front", "sensor_msgs/msg/Image", 5)]
    assert list_pose_topics(path) == []
    with open_recording(path, topic="/back") as src:
        assert src.frame_count == 3
        assert np.allclose(src.stamps(), [1.05, 1.15, 1.25])
        assert np.array_equal(src.frame_at(1).rgb, frames[11])
    with open_source(path, topic="/front") as src:
        assert src.frame_count == 5
        assert np.array_equal(src.frame_at(4).rgb, frames[4])


def test_bag_stamps_from_header_not_log_time(tmp_path, frames):
    # Logged late and out of capture order: frames follow the header stamps.
    msgs = [("/cam", 5.0, ros1_image(frames[0], 2.0)),
            ("/cam", 5.0, ros1_image(frames[1], 1.0)),   # same log time as the first
            ("/cam", 6.0, ros1_image(frames[2], 3.0))]
    path = write_messages_bag(tmp_path / "late.bag", msgs)
    with BagSource(path) as src:
        assert np.allclose(src.stamps(), [1.0, 2.0, 3.0])
        assert [mean_abs_error(src.frame_at(i).rgb, frames[j]) for i, j in
                [(0, 1), (1, 0), (2, 2)]] == [0.0, 0.0, 0.0]
        assert [f.index for f in src.frames(0.0)] == [0, 1, 2]
        assert np.array_equal(next(iter(src.frames(0.0))).rgb, frames[1])


# --- all formats agree ----------------------------------------------------------


def test_all_formats_decode_the_same_sampled_frames(recordings, frames):
    results = {}
    for kind in ["mp4", "ros1", "sqlite3", "mcap", "folder"]:
        with open_recording(recordings[kind]) as src:
            idx, stamps, rgbs = sampled(src, 1.0)
            results[kind] = (idx, np.asarray(stamps) - stamps[0], rgbs)
    ref_idx, ref_rel, ref_rgbs = results["ros1"]
    assert ref_idx == [0, 10, 20, 30]
    for kind, (idx, rel, rgbs) in results.items():
        assert idx == ref_idx, kind
        assert np.allclose(rel, ref_rel, atol=1e-6), kind
        bound = VIDEO_MAE if kind == "mp4" else 0.0
        for a, b in zip(rgbs, ref_rgbs):
            assert mean_abs_error(a, b) <= bound, kind


# --- poses ----------------------------------------------------------------------


def _poses(n: int = 20) -> Poses:
    t = 1700000000.0 + 0.05 * np.arange(n)
    yaw = np.linspace(-3.0, 3.0, n)
    return Poses(t=t, x=np.cos(yaw) * 4, y=np.sin(2 * yaw), yaw=yaw)


def test_poses_csv_round_trip(tmp_path):
    poses = _poses()
    got = read_poses(write_poses_csv(tmp_path / "p.csv", poses))
    for name in ["t", "x", "y", "yaw"]:
        assert np.array_equal(getattr(got, name), getattr(poses, name)), name
    (tmp_path / "q.csv").write_text("t,x,y\n2.0,1,1\n1.0,0,0\n")
    got = read_poses(tmp_path / "q.csv")
    assert got.yaw is None and np.array_equal(got.t, [1.0, 2.0]) and np.array_equal(got.x, [0, 1])


@pytest.mark.parametrize("kind,pose_type", [
    ("ros1", "odometry"), ("ros1", "posestamped"),
    ("sqlite3", "odometry"), ("mcap", "posestamped")])
def test_poses_from_bag_topic(tmp_path, frames, kind, pose_type):
    poses = _poses()
    stamps = poses.t[::5]
    if kind == "ros1":
        path = write_ros1_bag(tmp_path / "p.bag", frames[:4], stamps, poses=poses,
                              pose_topic="/gt", pose_type=pose_type)
    else:
        path = write_ros2_bag(tmp_path / "p", frames[:4], stamps, storage=kind, poses=poses,
                              pose_topic="/gt", pose_type=pose_type)
    msgtype = {"odometry": "nav_msgs/msg/Odometry",
               "posestamped": "geometry_msgs/msg/PoseStamped"}[pose_type]
    assert list_pose_topics(path) == [("/gt", msgtype, 20)]
    for got in [read_poses(path), read_poses(path, topic="/gt")]:
        assert np.allclose(got.t, poses.t, atol=1e-6)
        assert np.allclose(got.x, poses.x) and np.allclose(got.y, poses.y)
        assert np.allclose(got.yaw, poses.yaw, atol=1e-9)
    # the image topic of the same bag is still found on its own
    assert open_recording(path).frame_count == 4


def test_a_photo_folder_asked_for_narrower_frames_decodes_them_smaller(tmp_path):
    # A real photo (JPEG, as cameras write), decoded at a fraction of its size in libjpeg.
    pano = cv2.imread(str(Path(__file__).parent / "data" / "examplepano_1024.jpg"))
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"p{i}.jpg"), np.roll(pano, 100 * i, axis=1))
    src = FolderSource(tmp_path)
    small = list(src.frames(1.0, max_width=256))
    full = list(src.frames(1.0))
    assert [f.index for f in small] == [f.index for f in full]
    for s, f in zip(small, full):
        assert s.rgb.shape == (128, 256, 3) and s.source_width == 1024 and s.width == 1024
        shrunk = cv2.resize(f.rgb, (256, 128), interpolation=cv2.INTER_AREA)
        assert mean_abs_error(s.rgb, shrunk) < 6                 # the same picture, smaller
    # A frame of another size is still refused in one line, from its header.
    cv2.imwrite(str(tmp_path / "p3.jpg"), cv2.resize(pano, (512, 256)))
    from engine.errors import InputError

    with pytest.raises(InputError, match="image is 512x256, the folder's first image is 1024x512"):
        list(FolderSource(tmp_path).frames(1.0, max_width=256))
