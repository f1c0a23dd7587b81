"""Bad input to the readers gives InputError with a one-line reason."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from engine.errors import InputError
from engine.sources import open_source
from engine.poses import Poses
from engine.sources import (
    BagSource,
    FolderSource,
    list_image_topics,
    list_pose_topics,
    open_recording,
    read_poses,
)
from engine.synth.writers import (
    write_image_folder,
    write_ros1_bag,
    write_ros2_bag,
    write_video,
)
from test_sources_data import (
    make_frames,
    make_stamps,
    ros1_compressed,
    ros1_header,
    ros1_image,
    ros1_types,
    write_messages_bag,
)


def raises(match: str):
    """InputError whose one-line message matches ``match``."""
    return pytest.raises(InputError, match=match)


def one_line(excinfo) -> None:
    assert "\n" not in str(excinfo.value)


@pytest.fixture(scope="module")
def frames():
    return make_frames(4)


def test_missing_and_unsupported_paths(tmp_path):
    for call in [lambda p: open_recording(p), lambda p: open_source(p), read_poses,
                 list_image_topics, list_pose_topics]:
        with raises("no such file") as e:
            call(tmp_path / "nothing.bag")
        one_line(e)
    (tmp_path / "notes.txt").write_text("hello")
    with raises("unsupported file type '.txt'"):
        open_recording(tmp_path / "notes.txt")


@pytest.mark.parametrize("name,match", [
    ("garbage.mp4", "unreadable or unsupported video|no decodable frame"),
    ("garbage.bag", "unreadable ROS bag"),
    ("garbage.db3", "unreadable ROS bag"),
    ("garbage.mcap", "unreadable ROS bag"),
])
def test_unreadable_containers(tmp_path, name, match):
    rng = np.random.default_rng(1)
    (tmp_path / name).write_bytes(rng.integers(0, 256, 5000, dtype=np.uint8).tobytes())
    with raises(match) as e:
        open_recording(tmp_path / name)
    one_line(e)


def test_unreadable_ros2_metadata(tmp_path):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with raises("unreadable ROS bag"):
        open_recording(bag)


def test_directory_with_several_storage_files(tmp_path, frames):
    bag = write_ros2_bag(tmp_path / "b", frames, make_stamps(4))
    (bag / "metadata.yaml").unlink()
    (bag / "second.db3").write_bytes((bag / "b.db3").read_bytes())
    with raises("no metadata.yaml and 2 .db3/.mcap files"):
        open_recording(bag)


def test_bag_without_image_topic(tmp_path, frames):
    poses = Poses(t=make_stamps(3), x=np.zeros(3), y=np.zeros(3), yaw=np.zeros(3))
    msgs = [("/odom_only", 0.0, ros1_types().types["std_msgs/msg/String"](data="x"))]
    path = write_messages_bag(tmp_path / "s.bag", msgs)
    with raises(r"no image topic in this bag \(topics: /odom_only\)"):
        open_recording(path)
    with raises("no pose topic"):
        read_poses(path)
    path2 = write_ros2_bag(tmp_path / "p", frames, make_stamps(4), poses=poses)
    with raises("no pose topic '/nope'; available pose topics: /odom"):
        read_poses(path2, topic="/nope")


def test_unknown_and_ambiguous_topics(tmp_path, frames):
    msgs = [("/a", 1.0, ros1_image(frames[0], 1.0)), ("/b", 1.1, ros1_image(frames[1], 1.1))]
    path = write_messages_bag(tmp_path / "two.bag", msgs)
    with raises("several image topics, choose one with --topic: /a, /b") as e:
        open_recording(path)
    one_line(e)
    with raises("no image topic '/c'; available image topics: /a, /b"):
        open_recording(path, topic="/c")
    single = write_ros1_bag(tmp_path / "one.bag", frames, make_stamps(4))
    with raises("available image topics: /camera/image_raw"):
        open_source(single, topic="/camera/compressed")


def test_several_pose_topics(tmp_path):
    types = ros1_types().types
    pose = types["geometry_msgs/msg/PoseStamped"]
    p = types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
        orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    msgs = [("/gt1", 1.0, pose(header=ros1_header(1.0), pose=p)),
            ("/gt2", 1.0, pose(header=ros1_header(1.0), pose=p))]
    path = write_messages_bag(tmp_path / "poses.bag", msgs)
    with raises("several pose topics, choose one with --topic: /gt1, /gt2"):
        read_poses(path)
    assert read_poses(path, topic="/gt2").x.tolist() == [1.0]


def test_not_equirectangular(tmp_path):
    square = [np.full((64, 64, 3), 100, np.uint8)] * 3
    cases = [
        write_video(tmp_path / "sq.avi", square, 10),
        write_ros1_bag(tmp_path / "sq.bag", square, make_stamps(3)),
        write_ros2_bag(tmp_path / "sq", square, make_stamps(3), storage="mcap", compressed=True),
        write_image_folder(tmp_path / "sqimgs", square, make_stamps(3)),
    ]
    for path in cases:
        with raises("frame is 64x64, not an equirectangular 2:1 panorama") as e:
            open_recording(path)
        one_line(e)


def test_corrupt_compressed_frame(tmp_path, frames):
    good = cv2.imencode(".jpg", cv2.cvtColor(frames[0], cv2.COLOR_RGB2BGR))[1].tobytes()
    msgs = [("/cam", 1.0, ros1_compressed(good, 1.0)),
            ("/cam", 1.1, ros1_compressed(b"\xff\xd8 not really a jpeg", 1.1)),
            ("/cam", 1.2, ros1_compressed(good, 1.2))]
    path = write_messages_bag(tmp_path / "corrupt.bag", msgs)
    src = BagSource(path)  # the first frame is fine
    assert src.frame_count == 3
    with raises("frame 1 of /cam is corrupt"):
        src.frame_at(1)
    with raises("frame 1 of /cam is corrupt"):
        list(src.frames(0.0))
    assert src.frame_at(2).rgb.shape == (64, 128, 3)
    src.close()
    first_bad = write_messages_bag(tmp_path / "first.bag", msgs[1:2])
    with raises("frame 0 of /cam is corrupt"):
        open_recording(first_bad)


def test_truncated_raw_image(tmp_path, frames):
    msg = ros1_image(frames[0], 1.0)
    msg.data = msg.data[:1000]
    path = write_messages_bag(tmp_path / "short.bag", [("/cam", 1.0, msg)])
    with raises("frame 0 of /cam is corrupt or unsupported"):
        open_recording(path)


def test_folder_problems(tmp_path, frames):
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.md").write_text("no pictures")
    with raises("folder has no images") as e:
        open_recording(empty)
    one_line(e)

    bad = tmp_path / "bad"
    write_image_folder(bad, frames, make_stamps(4))
    (bad / "frame_000002.png").write_bytes(b"not a png")
    with raises("frame_000002.png: unreadable or corrupt image"):
        FolderSource(bad).frame_at(2)

    mixed = tmp_path / "mixed"
    write_image_folder(mixed, frames[:2] + [make_frames(1, 64, 32)[0]], make_stamps(3))
    with raises("image is 64x32, the folder's first image is 128x64"):
        FolderSource(mixed).frame_at(2)


@pytest.mark.parametrize("content,match", [
    ("0.0\n0.1\nabc\n0.3\n", r"line 3: 'abc' is not a stamp"),
    ("0.0\n0.1\n0.2\n", "3 stamps for 4 images"),
    ("0.0\n0.2\n0.1\n0.3\n", "stamps decrease in file name order"),
    ("0.0\n0.1\nnan\n0.3\n", "not finite"),
    ("filename,stamp\nframe_000000.png,0\nframe_000001.png,1\nframe_000002.png,2\n"
     "frame_000003.png,3\nother.png,4\n", "names images that are not in the folder: other.png"),
    ("filename,stamp\nframe_000000.png,0\nframe_000001.png,1\nframe_000003.png,3\n",
     r"no stamp for 1 image\(s\), e.g. frame_000002.png"),
    ("filename,stamp\nframe_000000.png;0\n", "line 2 must be 'filename,stamp'"),
])
def test_malformed_stamps_csv(tmp_path, frames, content, match):
    folder = write_image_folder(tmp_path / "f", frames, make_stamps(4))
    (folder / "stamps.csv").write_text(content)
    with raises(match) as e:
        open_recording(folder)
    one_line(e)


@pytest.mark.parametrize("content,match", [
    ("", "empty poses file"),
    ("time,x,y\n0,0,0\n", "header must be 't,x,y' or 't,x,y,yaw'"),
    ("t,x,y\n", "no poses after the header"),
    ("t,x,y\n0,1\n", "line 2 has 2 values, expected 3"),
    ("t,x,y,yaw\n0,1,2,3\n1,1,two,3\n", "line 3 is not numbers"),
    ("t,x,y\n0,1,inf\n", "non-finite"),
])
def test_malformed_poses_csv(tmp_path, content, match):
    (tmp_path / "p.csv").write_text(content)
    with raises(match) as e:
        read_poses(tmp_path / "p.csv")
    one_line(e)
