"""GoPro telemetry (GPMF): the KLV reader, the fix-quality rule, positions and headings.

KLV payloads are written by ``tests/cam360_clips.gpmf_payload`` following GoPro's published
layout (DEVC > STRM > SCAL/GPSF/GPSP/TYPE + GPS5/GPS9/CORI) and muxed as a real ``gpmd`` data
track (handler "GoPro MET") into a GoPro-style .360 clip with PyAV, then read back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

av = pytest.importorskip("av")

import cam360_clips as clips  # noqa: E402
from engine.errors import InputError  # noqa: E402
from engine.sources import gpmf, recording_headings, recording_poses  # noqa: E402

LAT0, LON0 = 45.5, 7.25
M_PER_DEG_LAT = 111_132.0   # near 45 degrees: 1e-5 degrees of latitude is about 1.11 m


def walk_north(n: int, step_deg: float = 1e-5, fix: int = 3, dop100: int = 150) -> list:
    return [(LAT0 + k * step_deg, LON0, 300.0, fix, dop100) for k in range(n)]


def samples(payload: bytes) -> gpmf.Telemetry:
    out = {"gps": [], "cori": [], "gyro": []}
    gpmf.payload_samples(payload, 0.0, 1.0, out)
    tel = gpmf.Telemetry()
    if out["gps"]:
        tel.gps_t, tel.gps, tel.fix, tel.dop = (np.concatenate([g[i] for g in out["gps"]]) for i in range(4))
    if out["cori"]:
        tel.cori_t, tel.cori = (np.concatenate([c[i] for c in out["cori"]]) for i in range(2))
    return tel


def test_gps5_values_are_scaled_to_degrees_and_metres():
    tel = samples(clips.gpmf_payload(walk_north(10)))
    assert tel.gps.shape == (10, 3)
    assert np.allclose(tel.gps[:, 0], LAT0 + np.arange(10) * 1e-5, atol=1e-7)
    assert np.allclose(tel.gps[:, 1], LON0, atol=1e-7) and np.allclose(tel.gps[:, 2], 300.0)
    assert np.all(tel.fix == 3) and np.allclose(tel.dop, 1.5)
    assert np.allclose(tel.gps_t, np.arange(10) / 10)       # spread evenly over the payload


def test_fixed_point_values_are_scaled_as_the_spec_says():
    """GPMF types q (Q15.16) and Q (Q31.32) are fixed-point numbers, also inside a complex TYPE."""
    import struct

    plain = struct.pack(">4scBH", b"TSTq", b"q", 4, 2) + struct.pack(">ii", 3 * 2 ** 15, -2 ** 14)
    wide = struct.pack(">4scBH", b"TSTQ", b"Q", 8, 1) + struct.pack(">q", 5 * 2 ** 31)
    (q,), (big,) = gpmf.parse_klv(plain), gpmf.parse_klv(wide)
    assert np.allclose(gpmf.values(q).ravel(), [1.5, -0.25]) and np.allclose(gpmf.values(big), 2.5)
    mixed = struct.pack(">4scBH", b"TSTC", b"?", 8, 1) + struct.pack(">ll", 7, 2 ** 17)
    assert np.allclose(gpmf.values(gpmf.parse_klv(mixed)[0], "lq"), [[7.0, 2.0]])


def test_gps9_carries_fix_and_precision_per_sample():
    fixes = walk_north(4)
    fixes[1] = fixes[1][:3] + (0, 150)        # no fix
    fixes[2] = fixes[2][:3] + (3, 900)        # DOP 9
    tel = samples(clips.gpmf_payload(fixes, gps9=True))
    assert tel.fix.tolist() == [3, 0, 3, 3] and np.allclose(tel.dop, [1.5, 1.5, 9.0, 1.5])
    assert gpmf.good_fixes(tel).tolist() == [True, False, False, True]


def test_positions_use_only_good_fixes_in_metres_from_the_first():
    fixes = walk_north(10)
    tel = samples(clips.gpmf_payload(fixes, gps9=True))
    tel.fix[:2] = 2                                          # a 2D fix is below the 3D rule
    poses, warnings = gpmf.gps_poses(tel)
    assert poses is not None and len(poses) == 8 and warnings and "2 of 10" in warnings[0]
    assert poses.x[0] == 0 and poses.y[0] == 0               # the first good fix is the origin
    assert np.allclose(poses.x, 0, atol=1e-6)
    assert np.allclose(np.diff(poses.y), 1e-5 * M_PER_DEG_LAT, rtol=0.01)   # 1.11 m a step, north


def test_too_few_good_fixes_give_no_positions():
    tel = samples(clips.gpmf_payload(walk_north(5, fix=0)))
    poses, warnings = gpmf.gps_poses(tel)
    assert poses is None and any("too few" in w for w in warnings)


def test_cori_yaw_of_a_turn_about_z():
    tel = samples(clips.gpmf_payload(walk_north(1), cori_yaw_deg=[0, 30, 60, 90, 120, 150, 170, -170]))
    assert np.allclose(np.degrees(gpmf.cori_yaw(tel.cori)), [0, 30, 60, 90, 120, 150, 170, -170], atol=0.05)
    mid = gpmf.headings_at(tel, [6.5 / 8])                   # between 170 and -170: across the wrap
    assert abs(abs(np.degrees(mid[0])) - 180) < 0.1


@pytest.mark.parametrize("cut", [3, 12, 30])
def test_a_damaged_payload_is_one_clear_line(cut):
    payload = clips.gpmf_payload(walk_north(5))
    bad = payload[:8] + payload[8:][:cut]     # the DEVC header still claims the whole body
    with pytest.raises(InputError) as err:
        gpmf.parse_klv(bad)
    assert "GPMF" in str(err.value) and "\n" not in str(err.value)


def test_a_compressed_gyro_stream_does_not_stop_the_gps_but_a_compressed_gps_stream_is_one_line():
    """Mapping never uses the gyroscope: a stream of it the reader cannot decode (GPMF's
    compressed type "#") is left out, and the GPS beside it read; GPS it cannot decode is a
    clear one-line error, never a map without the positions the file has."""
    payload = clips.gpmf_payload(walk_north(5))
    gyro = clips.nest("STRM", clips.klv("GYRO", "#", 4, 3, b"\x01\x02\x03\x04" * 3))
    body = gpmf.parse_klv(payload)[0].data + gyro
    tel = samples(clips.klv("DEVC", "", 1, len(body), body))
    assert tel.gps.shape == (5, 3)
    bad = clips.nest("DEVC", clips.nest("STRM", clips.klv("GPS5", "#", 4, 5, b"\0" * 20)))
    with pytest.raises(InputError) as err:
        samples(bad)
    assert "GPS5" in str(err.value) and "\n" not in str(err.value)


@pytest.fixture(scope="module")
def gopro_clip(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("gpmf")
    gps = walk_north(30, step_deg=2e-5)
    gps[0] = gps[0][:3] + (0, 9999)           # the first second has no fix yet
    gps = [gps[0]] + [g[:3] + (0, 9999) for g in gps[1:10]] + gps[10:]
    return clips.write_gopro_360(d / "GS010002.360", frames=30, gps=gps, cori_yaw_deg_per_s=20.0)


def test_the_gpmf_track_of_a_gopro_file_gives_positions_on_the_video_clock(gopro_clip):
    tel = gpmf.read_telemetry(gopro_clip)
    assert tel is not None and tel.gps_t.size == 30
    assert np.allclose(tel.gps_t, np.arange(30) / clips.FPS, atol=1e-6)
    poses, warnings = recording_poses(gopro_clip)
    assert poses is not None and "10 of 30" in warnings[0]   # the second without a fix is left out
    assert poses.t[0] == pytest.approx(1.0) and len(poses) == 20
    assert np.allclose(np.diff(poses.y), 2e-5 * M_PER_DEG_LAT, rtol=0.01) and np.allclose(poses.x, 0, atol=1e-6)


def test_headings_from_cori_at_frame_stamps(gopro_clip):
    stamps = np.array([0.0, 0.5, 1.0, 2.5])
    yaw = recording_headings(gopro_clip, stamps)
    assert np.allclose(np.degrees(yaw), 20.0 * stamps, atol=0.1)


def test_a_video_without_telemetry_has_no_positions_or_headings(tmp_path):
    path = clips.write_gopro_360(tmp_path / "plain.360", frames=3)
    assert gpmf.read_telemetry(path) is None
    assert recording_poses(path) == (None, []) and recording_headings(path, [0.0]) is None


def test_panotopo_map_of_a_gopro_clip_puts_gps_positions_on_nodes(gopro_clip, tmp_path, capsys):
    import networkx as nx

    from engine.cli import main

    out = tmp_path / "m.graphml"
    code = main(["map", str(gopro_clip), "-o", str(out), "--no-cache", "--input-height", "32", "-q",
                 "--interval", "0.2"])
    err = capsys.readouterr().err
    assert code == 0, err
    g = nx.read_graphml(out)
    assert g.graph["positions"] == "gps"
    nodes = sorted(g.nodes(data=True), key=lambda n: n[1]["index"])
    assert all("x" in d and "y" in d for _, d in nodes)
    ys = [d["y"] for _, d in nodes]
    assert ys == sorted(ys) and ys[-1] > ys[0]               # the walk goes north


@pytest.fixture(scope="module")
def turning_clips(tmp_path_factory) -> dict:
    """GoPro-style clips of a camera turning 56.25 degrees a second (the panorama rolled 8 of
    512 columns a frame at 10 fps), with CORI tracks that say so (either sign: which way the
    camera's z axis points is not known) or say something else."""
    d = tmp_path_factory.mktemp("turning")
    rate = clips.ROLL * 360.0 / clips.W * clips.FPS
    gps = walk_north(40)
    return {name: clips.write_gopro_360(d / f"{name}.360", frames=40, gps=gps, cori_yaw_deg_per_s=r)
            for name, r in (("plus", rate), ("minus", -rate), ("wrong", 2.7 * rate), ("still", 0.0))}


def test_cori_headings_are_used_when_the_pictures_agree_whatever_the_sign(turning_clips):
    from engine.shift import apply_shift, shift_from_heading
    from engine.sources import open_recording

    truth = None
    for name in ("plus", "minus"):
        with open_recording(turning_clips[name]) as src:
            h = src.headings()
            assert h is not None and h.shape == (src.frame_count,), src.heading_note
            assert "agree" in src.heading_note
            # the camera turned counter-clockwise: its clockwise heading falls 5.625 degrees a frame
            assert np.allclose(np.diff(np.unwrap(np.radians(h))), -np.radians(5.625), atol=np.radians(0.2))
            truth = h if truth is None else truth
            assert np.allclose(h, truth, atol=0.2)
            # every frame turned by its heading shows the same picture
            frames = [src.frame_at(k).rgb for k in (0, 13, 27)]
            shifted = [apply_shift(f, shift_from_heading(f.shape[1], h[k])) for f, k in zip(frames, (0, 13, 27))]
            assert all(np.abs(s.astype(int) - shifted[0]).mean() < 12 for s in shifted[1:])


@pytest.mark.parametrize("name", ["wrong", "still"])
def test_a_cori_track_the_pictures_do_not_confirm_is_not_used(turning_clips, name):
    from engine.sources import open_recording

    with open_recording(turning_clips[name]) as src:
        assert src.headings() is None
        assert "CORI" in src.heading_note


def test_describe_shifts_a_gopro_clip_by_its_checked_heading(turning_clips):
    from engine.pipeline import DescribeSettings, describe
    from engine.shift import shift_from_heading
    from engine.sources import open_recording

    descs = describe(turning_clips["plus"], DescribeSettings(interval=0.5, options={"input_height": 32}))
    assert descs.meta["shift_from"] == "heading"
    with open_recording(turning_clips["plus"]) as src:
        h = src.headings()
    expected = [shift_from_heading(clips.W, h[i]) for i in descs.frames]
    assert np.all(np.abs((descs.shifts - expected + clips.W // 2) % clips.W - clips.W // 2) <= 1)
