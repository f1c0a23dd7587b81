"""One corrupt frame need not end a run (issue 16, finding 13)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.errors import InputError
from engine.pipeline import DescribeSettings, describe
from test_sources_data import make_frames, ros1_image, write_messages_bag

ROOT = Path(__file__).resolve().parent.parent
OPTIONS = {"input_height": 32}   # the real model, small input: fast


@pytest.fixture
def folder_with_a_bad_image(tmp_path) -> Path:
    folder = tmp_path / "walk"
    folder.mkdir()
    for k, rgb in enumerate(make_frames(7, 128, 64)):
        cv2.imwrite(str(folder / f"f{k}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    (folder / "f3.png").write_bytes(b"\x89PNG\r\n\x1a\n this file was cut short")
    return folder


def _cli(capsys, *args) -> tuple[int, list[str]]:
    """``panotopo ARGS`` in this process (the model loads once for the whole file)."""
    from engine.cli import main

    code = main([str(a) for a in args])
    return code, capsys.readouterr().err.strip().splitlines()


def test_without_the_flag_the_error_names_the_frame_and_the_flag(folder_with_a_bad_image, tmp_path, capsys):
    code, lines = _cli(capsys, "describe", folder_with_a_bad_image, "-o", tmp_path / "d.npz", "--no-cache",
                       "--input-height", "32", "-q")
    assert code == 2
    assert len(lines) == 1 and "f3.png" in lines[0] and "--skip-bad-frames" in lines[0]


def test_with_the_flag_bad_frames_are_skipped_and_counted(folder_with_a_bad_image, tmp_path, capsys):
    out = tmp_path / "d.npz"
    code, lines = _cli(capsys, "describe", folder_with_a_bad_image, "-o", out, "--no-cache",
                       "--input-height", "32", "--skip-bad-frames", "-q")
    assert code == 0, lines
    assert len(lines) == 1 and "skipped 1 undecodable frame" in lines[0]
    with np.load(out) as z:
        meta = json.loads(str(z["meta"]))
        frames = z["frames"].tolist()
    assert meta["skipped_frames"] == [3]
    assert frames == [0, 1, 2, 4, 5, 6]


def test_a_bag_with_a_corrupt_message_is_read_around_it(tmp_path):
    frames = make_frames(6, 128, 64)
    messages = [("/cam", 10.0 + k, ros1_image(rgb, 10.0 + k)) for k, rgb in enumerate(frames)]
    cut = ros1_image(frames[2][:10], 12.0)   # frame 2: its data was cut short
    cut.height = 64
    messages[2] = ("/cam", 12.0, cut)
    bag = write_messages_bag(tmp_path / "r.bag", messages)
    settings = DescribeSettings(interval=0.0, options=OPTIONS)
    with pytest.raises(InputError, match="skip"):
        describe(bag, settings)
    descs = describe(bag, DescribeSettings(interval=0.0, options=OPTIONS, skip_bad_frames=True))
    assert descs.meta["skipped_frames"] == [2]
    assert descs.frames.tolist() == [0, 1, 3, 4, 5]


def test_a_damaged_png_prints_only_panotopos_line_not_libpngs(folder_with_a_bad_image, tmp_path, capfd):
    """libpng writes straight to descriptor 2: captured at that level (capfd), not sys.stderr."""
    from engine.cli import main

    code = main(["describe", str(folder_with_a_bad_image), "-o", str(tmp_path / "d.npz"), "--no-cache",
                 "--input-height", "32", "-q"])
    lines = capfd.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(lines) == 1 and lines[0].startswith("panotopo: error:") and "f3.png" in lines[0]
    assert not any("libpng" in line for line in lines)


@pytest.fixture
def cut_video(tmp_path) -> tuple[Path, int, int]:
    """An MP4 with its index at the front, cut short: (path, frames declared, frames readable)."""
    av = pytest.importorskip("av")
    from test_video_sampling import write_clip

    good = write_clip(tmp_path / "whole.mp4", gop=25, n=60, faststart=True).read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(good[: int(len(good) * 0.93)])
    with av.open(str(cut)) as c:
        stream = c.streams.video[0]
        declared = int(stream.frames)
        readable = sum(1 for p in c.demux(stream) if p.size and not p.is_corrupt)
    assert 0 < readable < declared == 60
    return cut, declared, readable


def test_a_video_cut_short_is_refused_with_the_hint_and_read_as_far_as_it_goes_with_the_flag(cut_video, tmp_path,
                                                                                             capsys):
    from test_video_sampling import frame_number

    path, declared, readable = cut_video
    code, lines = _cli(capsys, "describe", path, "-o", tmp_path / "no.npz", "--no-cache", "--input-height", "32",
                       "--interval", "0.1", "-q")
    assert code == 2 and len(lines) == 1
    assert f"{declared}" in lines[0] and "--skip-bad-frames" in lines[0]
    out = tmp_path / "d.npz"
    code, lines = _cli(capsys, "describe", path, "-o", out, "--no-cache", "--input-height", "32",
                       "--interval", "0.1", "--skip-bad-frames", "-q")
    assert code == 0, lines
    assert len(lines) == 1 and f"{readable} of the {declared}" in lines[0]
    with np.load(out) as z:
        frames = z["frames"].tolist()
        meta = json.loads(str(z["meta"]))
    assert frames and max(frames) < readable and meta["reader_notes"]
    from engine.sources import open_recording

    with open_recording(path, skip_bad_frames=True) as src:     # the pictures are the frames named
        for f in src.frames(0.4):
            assert frame_number(f.rgb) == f.index
