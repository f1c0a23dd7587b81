"""Geotagged photo folders: EXIF times order and stamp the photos, EXIF GPS gives positions.

Photos are real JPEGs written by Pillow with real EXIF (Exif IFD 0x8769, GPS IFD 0x8825).
Expected positions come from the textbook lengths of a degree (not from the code under
test): latitude 111132.954 - 559.822 cos 2p + 1.175 cos 4p m, longitude
111412.84 cos p - 93.5 cos 3p + 0.118 cos 5p m (accurate to centimetres per degree).
"""

from __future__ import annotations

import math
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from PIL import Image, TiffImagePlugin

from engine.cli import main
from engine.sources import FolderSource, open_recording, recording_poses
from engine.sources.exif import read_photo_tags

LAT0, LON0 = 49.0068896, 1.9191854  # the GoPro example's first fix (Normandy)
P = math.radians(LAT0)
M_PER_DEG_LAT = 111132.954 - 559.822 * math.cos(2 * P) + 1.175 * math.cos(4 * P)
M_PER_DEG_LON = 111412.84 * math.cos(P) - 93.5 * math.cos(3 * P) + 0.118 * math.cos(5 * P)


def dms(degrees: float) -> tuple:
    """Degrees as EXIF degrees, minutes, seconds rationals."""
    d = int(degrees)
    m = int((degrees - d) * 60)
    s = (degrees - d - m / 60) * 3600
    return (TiffImagePlugin.IFDRational(d), TiffImagePlugin.IFDRational(m),
            TiffImagePlugin.IFDRational(round(s * 1e6), 1_000_000))


def write_photo(path: Path, shade: int, time: str | None = None, subsec: str | None = None,
                east_m: float | None = None, north_m: float | None = None,
                heading: float | None = None) -> Path:
    """A 128x64 'panorama' JPEG, with EXIF capture time and GPS fix where given."""
    rng = np.random.default_rng(shade)
    rgb = rng.integers(0, 256, (64, 128, 3), dtype=np.uint8)
    exif = Image.Exif()
    if time is not None:
        exif[0x8769] = {0x9003: time, **({0x9291: subsec} if subsec else {})}
    if north_m is not None:
        lat = LAT0 + north_m / M_PER_DEG_LAT
        lon = LON0 + east_m / M_PER_DEG_LON
        gps = {1: "N", 2: dms(lat), 3: "E", 4: dms(lon)}
        if heading is not None:
            gps.update({16: "T", 17: TiffImagePlugin.IFDRational(round(heading * 100), 100)})
        exif[0x8825] = gps
    Image.fromarray(rgb).save(path, quality=90, exif=exif)
    return path


@pytest.fixture()
def walk_north(tmp_path) -> Path:
    """4 photos 10 m apart walking north, 2.5 s apart; names NOT in time order."""
    names = ["d.jpg", "b.jpg", "a.jpg", "c.jpg"]  # d is first in time
    times = [("2024:05:01 10:00:00", "0"), ("2024:05:01 10:00:02", "5"),
             ("2024:05:01 10:00:05", "00"), ("2024:05:01 10:00:07", "50")]
    for k, (name, (t, sub)) in enumerate(zip(names, times)):
        write_photo(tmp_path / name, k, t, sub, east_m=0.0, north_m=10.0 * k, heading=0.0)
    return tmp_path


def test_exif_time_orders_and_stamps_and_gps_gives_metres(walk_north):
    with open_recording(walk_north) as src:
        assert isinstance(src, FolderSource)
        assert [f.name for f in src.files] == ["d.jpg", "b.jpg", "a.jpg", "c.jpg"]
        assert np.allclose(src.stamps(), [0.0, 2.5, 5.0, 7.5], atol=1e-6)
        poses = src.poses
        assert poses is not None and not src.warnings
        assert np.allclose(poses.t, src.stamps())
        assert np.allclose(poses.y, [0.0, 10.0, 20.0, 30.0], atol=0.1)
        assert np.allclose(poses.x, 0.0, atol=0.1)
        assert np.allclose(poses.yaw, math.pi / 2)  # heading north = +y = 90 degrees from east


def test_east_and_south_offsets_have_the_right_signs(tmp_path):
    for k, (east, north) in enumerate([(0, 0), (25, 0), (25, -40), (-15, -40)]):
        write_photo(tmp_path / f"{k}.jpg", k, f"2024:05:01 10:00:0{k}", east_m=east, north_m=north,
                    heading=90.0 * k)
    poses, warnings = recording_poses(tmp_path)
    assert not warnings
    assert np.allclose(poses.x, [0, 25, 25, -15], atol=0.1)
    assert np.allclose(poses.y, [0, 0, -40, -40], atol=0.1)
    # headings N, E, S, W are yaws +90, 0, -90, 180 degrees (counter-clockwise from east)
    assert np.allclose(np.cos(poses.yaw), [0, 1, 0, -1], atol=1e-6)
    assert np.allclose(np.sin(poses.yaw), [1, 0, -1, 0], atol=1e-6)


def test_a_photo_without_exif_means_name_order_index_stamps_and_no_positions(walk_north):
    write_photo(walk_north / "e.jpg", 9)  # no EXIF at all
    with FolderSource(walk_north, interval=1.0) as src:
        assert [f.name for f in src.files] == ["a.jpg", "b.jpg", "c.jpg", "d.jpg", "e.jpg"]
        assert np.allclose(src.stamps(), [0, 1, 2, 3, 4])
        assert src.poses is None
        assert any("capture time" in w for w in src.warnings)
        assert any("GPS" in w for w in src.warnings)


def test_malformed_fields_are_skipped_with_a_warning(tmp_path):
    bad = tmp_path / "bad.jpg"
    exif = Image.Exif()
    exif[0x8769] = {0x9003: "yesterday"}
    exif[0x8825] = {1: "Q", 2: (1.0, 2.0, 3.0), 3: "E", 4: (1.0, 2.0, 3.0), 17: 400.0}
    Image.new("RGB", (64, 32)).save(bad, exif=exif)
    tags = read_photo_tags(bad)
    assert (tags.time, tags.latitude, tags.longitude, tags.direction) == (None, None, None, None)
    text = " ".join(tags.warnings)
    for field in ("DateTimeOriginal", "GPSLatitude", "GPSImgDirection"):
        assert field in text
    assert all("\n" not in w for w in tags.warnings)
    junk = tmp_path / "junk.jpg"  # an APP1 segment that is not TIFF at all
    Image.new("RGB", (64, 32)).save(junk, exif=b"Exif\x00\x00not a tiff header at all")
    tags = read_photo_tags(junk)
    assert tags.time is None and not tags.has_fix


def test_map_puts_gps_positions_on_nodes_and_explicit_poses_win(walk_north, tmp_path, capsys):
    out = tmp_path / "gps.graphml"
    assert main(["map", str(walk_north), "-o", str(out), "--quiet", "--input-height", "64",
                 "--cache-dir", str(tmp_path / "cache")]) == 0
    g = nx.read_graphml(out)
    for _, node in g.nodes(data=True):
        assert node["x"] == pytest.approx(0.0, abs=0.1)
        assert node["y"] == pytest.approx(node["stamp"] * 4.0, abs=0.1)  # 10 m per 2.5 s
    csv = tmp_path / "poses.csv"
    csv.write_text("t,x,y\n0,100,0\n10,200,0\n")
    out2 = tmp_path / "explicit.graphml"
    assert main(["map", str(walk_north), "-o", str(out2), "--quiet", "--input-height", "64", "--poses", str(csv),
                 "--cache-dir", str(tmp_path / "cache")]) == 0
    for _, node in nx.read_graphml(out2).nodes(data=True):
        assert node["x"] == pytest.approx(100.0 + 10.0 * node["stamp"])


def _shared_real() -> Path | None:
    for root in (Path(__file__).resolve().parents[2] / "shared", Path("/work/shared")):
        folder = root / "data" / "real" / "panoramax-gopromax"
        if folder.is_dir():
            return folder
    return None


@pytest.mark.skipif(_shared_real() is None, reason="shared/data/real is not here")
def test_real_gopro_folder_walks_about_nine_metres_north():
    poses, warnings = recording_poses(_shared_real())
    assert not warnings and poses is not None and len(poses) == 5
    assert np.all(np.diff(poses.t) > 0)
    assert 8.0 < poses.y[-1] - poses.y[0] < 11.0          # the README: about 9 m north
    assert np.all(np.diff(poses.y) > 0)                   # always northwards
    assert np.ptp(poses.x) < 2.0                          # along a road, little east-west
