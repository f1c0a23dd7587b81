"""Dual-fisheye and GoPro EAC recordings are converted to equirectangular as they are read.

The clips are real files in the cameras' layouts (``tests/cam360_clips.py``: our panorama
turned into fisheyes / EAC faces by FFmpeg's v360 and encoded with libx264 / libx265), read
back through ``open_recording``; each converted frame is measured against the panorama it
was made from. Tolerance: mean absolute error under ``TOL`` (of 255) over the whole frame;
the same measure between two different frames of the clips is about 30, so a wrong
projection, lens order, field of view or frame cannot pass.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

av = pytest.importorskip("av")

import cam360_clips as clips  # noqa: E402
from engine.errors import InputError  # noqa: E402
from engine.sources import open_recording  # noqa: E402
from engine.sources.projected import ProjectedSource  # noqa: E402
from engine.sources.projection import (Converter, Projection, gopro_columns, parse_projection,  # noqa: E402
                                       projection_from_streams, StreamShape)
from engine.sources.video import VideoSource  # noqa: E402
from engine.sources.video_360 import Video360Source  # noqa: E402

TOL = 10.0        # measured 5.4-6.8 for these clips (v360 twice + H.264/HEVC at this small size)
WRONG = 20.0      # a different frame or a wrong geometry is above this


def error(rgb: np.ndarray, k: int) -> float:
    return float(np.abs(rgb.astype(np.int16) - clips.panorama(k).astype(np.int16)).mean())


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cam360")
    return {
        "insv": clips.write_insv(d / "one_x.insv"),
        "insv2": clips.write_insv(d / "x3.insv", two_streams=True),
        "gopro": clips.write_gopro_360(d / "GS010001.360"),
    }


@pytest.mark.parametrize("name,layout", [("insv", "side-by-side"), ("insv2", "two-streams"), ("gopro", "gopro")])
def test_camera_files_are_detected_and_converted_within_tolerance(files, name, layout):
    with open_recording(files[name]) as src:
        assert isinstance(src, Video360Source)
        assert src.projection.layout == layout and src.projection.source == "container"
        assert src.resolution == (clips.W, clips.H)
        got = list(src.frames(0.5))
        assert [f.index for f in got] == list(range(0, 20, 5))
        for f in got:
            assert f.rgb.shape == (clips.H, clips.W, 3)
            assert f.stamp == pytest.approx(f.index / clips.FPS, abs=1e-6)
            assert error(f.rgb, f.index) < TOL
            assert error(f.rgb, f.index + 5) > WRONG        # the measure tells frames apart
        again = src.frame_at(7)                            # random access, same conversion
        assert again.index == 7 and error(again.rgb, 7) < TOL


def test_frames_asked_for_narrower_come_converted_to_that_width(files):
    with open_recording(files["gopro"]) as src:
        small = next(iter(src.frames(1.0, max_width=clips.W // 2)))
    assert small.rgb.shape == (clips.H // 2, clips.W // 2, 3) and small.width == clips.W
    import cv2

    truth = cv2.resize(clips.panorama(0), (clips.W // 2, clips.H // 2), interpolation=cv2.INTER_AREA)
    assert np.abs(small.rgb.astype(int) - truth).mean() < TOL


def test_the_lens_field_of_view_matters_and_can_be_given(files):
    with open_recording(files["insv"], projection="dual-fisheye:fov=180") as src:
        assert src.projection.fov == 180 and src.projection.source == "option"
        wrong = error(next(iter(src.frames(1.0))).rgb, 0)
    assert wrong > 1.5 * TOL


def test_a_lens_recorded_upside_down_is_turned_back_by_the_roll_option(tmp_path):
    path = clips.write_insv(tmp_path / "flipped.insv", frames=4, turns=(0, 2))
    with open_recording(path) as src:                      # the file does not say: wrong picture
        assert error(next(iter(src.frames(1.0))).rgb, 0) > 1.5 * TOL
    with open_recording(path, projection="dual-fisheye:fov=200,roll=0/180") as src:
        assert error(next(iter(src.frames(1.0))).rgb, 0) < TOL


def test_gopro_overlap_columns_are_dropped_exactly():
    pano = clips.panorama(0)
    face, extra = 128, 4
    eac = clips.v360(pano, f"input=e:output=eac:w={3 * face}:h={2 * face}")
    top, bottom = clips.gopro_strips(pano, face, extra)
    assert top.shape == (face, 3 * face + 2 * extra, 3)
    cols = gopro_columns(top.shape[1], face, extra)
    assert np.array_equal(np.vstack([top[:, cols], bottom[:, cols]]), eac)
    # the real 5.6K strip: faces 1376 | 1344 | 1376, 32 overlap columns in each side face
    cols = gopro_columns(4096, 1344, 32)
    assert cols.size == 3 * 1344 and np.all(np.diff(cols) > 0)
    assert 672 - 1 in cols and 672 not in cols and 703 not in cols and 704 in cols


def test_detection_rules_from_stream_shapes():
    gopro = [StreamShape(4096, 1344, "GoPro H.265"), StreamShape(4096, 1344, "GoPro H.265")]
    assert projection_from_streams(gopro, ".360").layout == "gopro"
    assert projection_from_streams(gopro, ".360").extra == 32
    assert projection_from_streams([StreamShape(2272, 736)] * 2, ".360").extra == 32
    assert projection_from_streams([StreamShape(2880, 2880)] * 2, ".insv").layout == "two-streams"
    insv = projection_from_streams([StreamShape(5760, 2880)], ".insv")
    assert (insv.name, insv.layout, insv.fov) == ("dual-fisheye", "side-by-side", 200.0)
    assert projection_from_streams([StreamShape(3840, 1920)], ".mp4").name == "equirect"
    forced = projection_from_streams([StreamShape(3840, 1920)], ".mp4", parse_projection("dual-fisheye"))
    assert forced.name == "dual-fisheye" and forced.fov == 190.0


@pytest.mark.parametrize("text", ["fisheye", "dual-fisheye:fov=90", "dual-fisheye:fov", "eac:layout=x",
                                  "dual-fisheye:roll=1", "dual-fisheye:fov=nan", "equirect:zoom=2"])
def test_a_bad_projection_option_is_one_line(text):
    with pytest.raises(InputError) as err:
        parse_projection(text)
    assert "--projection" in str(err.value) and "\n" not in str(err.value)


def test_an_equirectangular_video_is_read_as_before(tmp_path):
    path = tmp_path / "pano.mp4"
    with av.open(str(path), "w") as out:
        s = out.add_stream("libx264", rate=clips.FPS)
        s.width, s.height, s.pix_fmt = clips.W, clips.H, "yuv420p"
        for k in range(5):
            for p in s.encode(av.VideoFrame.from_ndarray(clips.panorama(k), format="rgb24")):
                out.mux(p)
        for p in s.encode(None):
            out.mux(p)
    with open_recording(path) as src:
        assert isinstance(src, VideoSource)
        assert error(src.frame_at(2).rgb, 2) < 4


def test_a_dual_fisheye_bag_is_converted_with_the_projection_option(tmp_path):
    pytest.importorskip("rosbags")
    from test_sources_data import ros1_image, write_messages_bag

    frames = [clips.dual_fisheye(clips.panorama(k), 190.0, clips.H) for k in range(4)]
    bag = write_messages_bag(tmp_path / "dfe.bag",
                             [("/cam", 5.0 + k, ros1_image(f, 5.0 + k)) for k, f in enumerate(frames)])
    with open_recording(bag, projection="dual-fisheye") as src:
        assert isinstance(src, ProjectedSource) and src.projection.fov == 190.0
        got = list(src.frames(0.0))
        assert [f.index for f in got] == [0, 1, 2, 3]
        assert [f.stamp for f in got] == pytest.approx([5.0, 6.0, 7.0, 8.0])
        for f in got:
            assert error(f.rgb, f.index) < TOL
        assert error(src.frame_at(3).rgb, 3) < TOL


def test_a_two_stream_projection_cannot_be_forced_on_a_bag(tmp_path):
    pytest.importorskip("rosbags")
    from test_sources_data import ros1_image, write_messages_bag

    bag = write_messages_bag(tmp_path / "b.bag", [("/cam", 1.0, ros1_image(clips.panorama(0), 1.0))])
    with pytest.raises(InputError, match="two video streams"):
        open_recording(bag, projection="dual-fisheye:layout=two-streams")


def test_converter_output_is_an_equirectangular_panorama():
    conv = Converter(Projection("eac", "eac"), [(384, 256)], out_width=200)
    out = conv([np.zeros((256, 384, 3), np.uint8)])
    assert out.shape == (100, 200, 3) and conv.native == (512, 256)


def _cli(capsys, *args) -> tuple[int, list[str]]:
    from engine.cli import main

    code = main([str(a) for a in args])
    return code, capsys.readouterr().err.strip().splitlines()


def test_panotopo_maps_camera_files_without_options(files, tmp_path, capsys):
    import networkx as nx

    for name in ("insv", "gopro"):
        out = tmp_path / f"{name}.graphml"
        code, lines = _cli(capsys, "map", files[name], "-o", out, "--no-cache", "--input-height", "32", "-q",
                           "--interval", "0.2")
        assert code == 0, lines
        g = nx.read_graphml(out)
        assert g.number_of_nodes() >= 1
        npz = tmp_path / f"{name}.npz"
        code, lines = _cli(capsys, "describe", files[name], "-o", npz, "--no-cache", "--input-height", "32", "-q",
                           "--interval", "0.2")
        assert code == 0, lines
        with np.load(npz) as z:
            meta = json.loads(str(z["meta"]))
        assert meta["projection"]["name"] == ("dual-fisheye" if name == "insv" else "eac")
        assert meta["frame_width"] == clips.W


def test_an_insta360_recording_in_two_files_opens_from_either(tmp_path):
    lens0, lens1 = clips.write_insv_pair(tmp_path, frames=10)
    for path in (lens0, lens1):
        with open_recording(path) as src:
            assert isinstance(src, Video360Source) and src.projection.layout == "two-streams"
            got = list(src.frames(0.5))
            assert [f.index for f in got] == [0, 5]
            assert all(error(f.rgb, f.index) < TOL for f in got)
    alone = tmp_path / "alone"
    alone.mkdir()
    lens0.rename(alone / lens0.name)                   # the other lens's file is missing
    with pytest.raises(InputError) as err:
        with open_recording(alone / lens0.name) as src:
            list(src.frames(1.0))
    assert "not an equirectangular" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("name,option", [("gopro", "dual-fisheye"), ("insv", "eac"), ("insv2", "eac:layout=eac")])
def test_a_projection_the_frames_cannot_have_is_refused_in_one_line(files, name, option):
    with pytest.raises(InputError) as err:
        with open_recording(files[name], projection=option) as src:
            list(src.frames(1.0))
    message = str(err.value)
    assert files[name].name in message and "--projection" in message and "\n" not in message


def test_the_meta_gives_the_option_back():
    from engine.sources.projection import projection_option

    p = parse_projection("dual-fisheye:fov=195,roll=0/180")
    again = parse_projection(projection_option({"projection": p.as_meta()}))
    assert (again.name, again.layout, again.fov, again.roll) == (p.name, p.layout, p.fov, p.roll)
    assert projection_option({"projection": {"name": "equirect"}}) is None and projection_option({}) is None


def test_panotopo_maps_a_dual_fisheye_bag_with_one_projection_option(tmp_path, capsys):
    pytest.importorskip("rosbags")
    import networkx as nx

    from test_sources_data import ros1_image, write_messages_bag

    frames = [clips.dual_fisheye(clips.panorama(3 * k), 190.0, clips.H) for k in range(8)]
    bag = write_messages_bag(tmp_path / "dfe.bag",
                             [("/cam", 5.0 + k, ros1_image(f, 5.0 + k)) for k, f in enumerate(frames)])
    out = tmp_path / "bag.graphml"
    code, lines = _cli(capsys, "map", bag, "-o", out, "--no-cache", "--input-height", "32", "-q",
                       "--projection", "dual-fisheye")
    assert code == 0, lines
    g = nx.read_graphml(out)
    assert g.graph["projection"] == "dual-fisheye" and g.number_of_nodes() >= 1


def test_side_by_side_fisheyes_in_a_plain_file_are_refused_until_the_option_says_what_they_are(tmp_path):
    """A 2:1 frame of two fisheyes has a panorama's shape: read as one it would be a wrong
    picture with exit 0. The black around the image circles gives it away."""
    from engine.sources.projection import looks_like_dual_fisheye

    assert looks_like_dual_fisheye(clips.dual_fisheye(clips.panorama(0), 190.0, 128))
    assert not looks_like_dual_fisheye(clips.panorama(0))
    assert not looks_like_dual_fisheye(np.zeros((128, 256, 3), np.uint8))    # a black frame is no lens
    path = clips.write_insv(tmp_path / "exported.mp4", frames=4)             # no .insv to say so
    with pytest.raises(InputError) as err:
        open_recording(path)
    assert "--projection dual-fisheye" in str(err.value) and "\n" not in str(err.value)
    with open_recording(path, projection="dual-fisheye:fov=200") as src:
        assert error(next(iter(src.frames(1.0))).rgb, 0) < TOL
    with open_recording(path, projection="equirect") as src:                  # the user's word wins
        assert isinstance(src, VideoSource)
    pytest.importorskip("rosbags")
    from test_sources_data import ros1_image, write_messages_bag

    bag = write_messages_bag(tmp_path / "dfe.bag", [("/cam", 1.0, ros1_image(clips.dual_fisheye(
        clips.panorama(0), 190.0, clips.H), 1.0))])
    with pytest.raises(InputError, match="--projection dual-fisheye"):
        open_recording(bag)
