"""The GPMF reader on real GoPro files: GoPro's own samples (tests/data/gpmf/README.md).

No expected value here comes from the reader itself. The tests state physical properties
(gravity, unit quaternions, walking and flying speeds, the Earth's magnetic field) or
compare the reader with an independent source written here from the GPMF and MP4 specs:
``klv`` walks a payload's items with ``struct``, ``gpmd_samples`` finds the telemetry
track's samples through the MP4 sample tables (stsd/stsz/stsc/stco/stts), not PyAV.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

av = pytest.importorskip("av")

from engine.sources import gpmf  # noqa: E402

DATA = Path(__file__).parent / "data" / "gpmf"
RAW = ["hero5.raw", "hero6.raw", "hero6+ble.raw", "karma.raw", "Fusion.raw"]
MAX_MP4 = DATA / "max-heromode.mp4"
G = 9.80665
EARTH_RADIUS_M = 6_371_000.0


# --- an independent reading, from the specs --------------------------------------------

def klv(buf: bytes, path: tuple = ()):
    """(path of container keys, key, type, size, repeat, data) of every leaf item in ``buf``."""
    pos = 0
    while pos + 8 <= len(buf):
        key, typ, size, repeat = buf[pos:pos + 4].decode("latin-1"), buf[pos + 4], buf[pos + 5], \
            int.from_bytes(buf[pos + 6:pos + 8], "big")
        data = buf[pos + 8:pos + 8 + size * repeat]
        if typ == 0 and key != "\0\0\0\0":
            yield from klv(data, path + (key,))
        else:
            yield path, key, chr(typ), size, repeat, data
        pos += 8 + (size * repeat + 3) // 4 * 4


def streams(buf: bytes) -> list[dict]:
    """Per STRM: its items by key (the last of a key), plus "_dev" its device's name."""
    out = []

    def walk(b: bytes, dev: str = ""):
        pos = 0
        while pos + 8 <= len(b):
            key, size = b[pos:pos + 4].decode("latin-1"), b[pos + 5]
            repeat = int.from_bytes(b[pos + 6:pos + 8], "big")
            data = b[pos + 8:pos + 8 + size * repeat]
            if key == "DEVC":
                name = next((d.decode("latin-1") for _, k, _, _, _, d in klv(data) if k == "DVNM"), "")
                walk(data, name)
            elif key == "STRM":
                items = {"_dev": dev}
                for _, k, t, s, r, d in klv(data):
                    items[k] = (t, s, r, d)
                out.append(items)
            pos += 8 + (size * repeat + 3) // 4 * 4

    walk(buf)
    return out


_FMT = {"b": "b", "B": "B", "s": "h", "S": "H", "l": "i", "L": "I", "f": "f", "d": "d", "j": "q", "J": "Q"}


def numbers(item, complex_type: str = "") -> np.ndarray:
    """An item's samples as rows of floats, decoded with ``struct`` (big-endian)."""
    typ, size, repeat, data = item
    if typ == "?":
        fmt = ">" + "".join(_FMT[c] for c in complex_type)
    else:
        fmt = ">" + _FMT[typ] * (size // struct.calcsize(">" + _FMT[typ]))
    return np.array([struct.unpack_from(fmt, data, k * size) for k in range(repeat)], dtype=np.float64)


def scaled(strm: dict, key: str) -> np.ndarray:
    ctype = strm["TYPE"][3].decode("latin-1").rstrip("\0") if "TYPE" in strm else ""
    v = numbers(strm[key], ctype)
    if "SCAL" in strm:
        s = numbers(strm["SCAL"]).ravel()
        v = v / (s if s.size == v.shape[1] else s[0])
    return v


def boxes(buf: bytes, start: int, end: int):
    """(type, payload start, payload end) of the ISO-BMFF boxes in buf[start:end]."""
    pos = start
    while pos + 8 <= end:
        size, typ = struct.unpack_from(">I4s", buf, pos)
        head = 8
        if size == 1:
            size, head = struct.unpack_from(">Q", buf, pos + 8)[0], 16
        elif size == 0:
            size = end - pos
        yield typ.decode("latin-1"), pos + head, pos + size
        pos += size


def child(buf: bytes, span: tuple, *path: str) -> tuple:
    for name in path:
        span = next((s, e) for t, s, e in boxes(buf, *span) if t == name)
    return span


def mp4_tracks(path: Path) -> dict:
    """Per track by its stsd format: timescale, duration (s), sample payloads and starts (s)."""
    buf = path.read_bytes()
    moov = next((s, e) for t, s, e in boxes(buf, 0, len(buf)) if t == "moov")
    tracks = {}
    for t, s, e in boxes(buf, *moov):
        if t != "trak":
            continue
        mdhd = child(buf, (s, e), "mdia", "mdhd")
        version = buf[mdhd[0]]
        timescale, duration = (struct.unpack_from(">I I", buf, mdhd[0] + 12) if version == 0
                               else struct.unpack_from(">I Q", buf, mdhd[0] + 20))
        stbl = child(buf, (s, e), "mdia", "minf", "stbl")
        stsd = child(buf, stbl, "stsd")
        fmt = buf[stsd[0] + 12:stsd[0] + 16].decode("latin-1")
        z = child(buf, stbl, "stsz")[0]
        fixed, count = struct.unpack_from(">II", buf, z + 4)
        sizes = [fixed] * count if fixed else list(struct.unpack_from(f">{count}I", buf, z + 12))
        kinds = {t2 for t2, _, _ in boxes(buf, *stbl)}
        co = child(buf, stbl, "stco" if "stco" in kinds else "co64")[0]
        n_chunks = struct.unpack_from(">I", buf, co + 4)[0]
        offsets = struct.unpack_from(f">{n_chunks}{'I' if 'stco' in kinds else 'Q'}", buf, co + 8)
        c = child(buf, stbl, "stsc")[0]
        n = struct.unpack_from(">I", buf, c + 4)[0]
        runs = [struct.unpack_from(">III", buf, c + 8 + 12 * k)[:2] for k in range(n)]
        a = child(buf, stbl, "stts")[0]
        n = struct.unpack_from(">I", buf, a + 4)[0]
        deltas = [d for k in range(n) for d in [struct.unpack_from(">II", buf, a + 8 + 8 * k)[1]]
                  * struct.unpack_from(">I", buf, a + 8 + 8 * k)[0]]
        payloads, k = [], 0
        for chunk, off in enumerate(offsets, start=1):
            per = next(spc for first, spc in reversed(runs) if first <= chunk)
            for _ in range(per):
                payloads.append(buf[off:off + sizes[k]])
                off += sizes[k]
                k += 1
        starts = np.concatenate([[0], np.cumsum(deltas)[:-1]]) / timescale
        tracks[fmt] = {"duration": duration / timescale, "payloads": payloads, "starts": starts,
                       "durations": np.asarray(deltas) / timescale}
    return tracks


def haversine_m(lat1, lon1, lat2, lon2):
    p1, p2 = np.radians(lat1), np.radians(lat2)
    dp, dl = p2 - p1, np.radians(np.asarray(lon2) - np.asarray(lon1))
    h = np.sin(dp / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(h))


def reader_samples(payload: bytes) -> dict:
    out = {"gps": [], "cori": [], "gyro": []}
    gpmf.payload_samples(payload, 0.0, 1.0, out)
    return out


@pytest.fixture(scope="module")
def max_tracks():
    return mp4_tracks(MAX_MP4)


@pytest.fixture(scope="module")
def max_tel():
    tel = gpmf.read_telemetry(MAX_MP4)
    assert tel is not None
    return tel


# --- raw payloads -------------------------------------------------------------------------

@pytest.mark.parametrize("name", RAW)
def test_raw_payload_parses_into_its_devices_and_streams(name):
    buf = (DATA / name).read_bytes()
    top = gpmf.parse_klv(buf)
    assert top and all(d.key == "DEVC" and d.type == "\0" for d in top)
    ours = [[c.key for c in s.children] for d in top for s in d.children if s.key == "STRM"]
    theirs = [[k for k in s if k != "_dev"] for s in streams(buf)]
    assert [sorted(set(k)) for k in ours] == [sorted(set(k)) for k in theirs]
    reader_samples(buf)                      # no InputError on any real stream of the payload


@pytest.mark.parametrize("name", RAW)
def test_accelerometer_reads_gravity(name):
    """A handheld or hovering camera: the median |ACCL| is g, no sample beyond 4 g."""
    for strm in streams((DATA / name).read_bytes()):
        if "ACCL" in strm:
            mag = np.linalg.norm(scaled(strm, "ACCL"), axis=1)
            assert abs(np.median(mag) - G) < 1.0 and mag.max() < 4 * G
            return
    pytest.fail("no ACCL")


@pytest.mark.parametrize("name", RAW)
def test_gyro_rates_match_an_independent_decode_and_are_plausible(name):
    buf = (DATA / name).read_bytes()
    strm = next(s for s in streams(buf) if "GYRO" in s)
    expected = scaled(strm, "GYRO")
    got = np.concatenate([g[1] for g in reader_samples(buf)["gyro"]])
    assert np.allclose(got, expected)
    assert np.median(np.linalg.norm(got, axis=1)) < np.pi   # mostly under half a turn a second


def test_fusion_magnetometer_reads_the_earths_field():
    """MAGN in microtesla (SIUN "µT"): the Earth's field is 25-65 µT."""
    strm = next(s for s in streams((DATA / "Fusion.raw").read_bytes()) if "MAGN" in s)
    assert strm["SIUN"][3].decode("latin-1") == "\xb5T"
    assert 25 < np.median(np.linalg.norm(scaled(strm, "MAGN"), axis=1)) < 65


@pytest.mark.parametrize("name", ["hero5.raw", "hero6.raw", "hero6+ble.raw", "Fusion.raw"])
def test_gps5_matches_an_independent_decode_fix_and_dop(name):
    buf = (DATA / name).read_bytes()
    strm = next(s for s in streams(buf) if "GPS5" in s)
    v = scaled(strm, "GPS5")
    fix, dop = numbers(strm["GPSF"])[0, 0], numbers(strm["GPSP"])[0, 0] / 100
    t, lla, fixes, dops = (np.concatenate(x) for x in zip(*reader_samples(buf)["gps"]))
    assert np.allclose(lla, v[:, :3]) and np.all(fixes == fix) and np.allclose(dops, dop)
    assert np.all(np.abs(lla[:, 0]) <= 90) and np.all(np.abs(lla[:, 1]) <= 180)
    tel = gpmf.Telemetry(gps_t=t, gps=lla, fix=fixes, dop=dops)
    # GoPro's rule: a 3D fix (GPSF 3) with GPSP under 500 is good; GPSF 0 / GPSP 9999 is not
    assert np.all(gpmf.good_fixes(tel) == (fix >= 3 and dop < 5))


@pytest.mark.parametrize("name", ["hero5.raw", "Fusion.raw"])
def test_gps5_steps_agree_with_the_receivers_speed(name):
    """Within one payload (about 1 s, samples spread evenly): the distance covered agrees with
    the receiver's own 2D speed (GPS5 column 4) -- consistent positions, right scales."""
    strm = next(s for s in streams((DATA / name).read_bytes()) if "GPS5" in s)
    v = scaled(strm, "GPS5")
    covered = haversine_m(v[0, 0], v[0, 1], v[-1, 0], v[-1, 1])
    dt = (len(v) - 1) / len(v)                # seconds, for a 1 s payload
    assert covered < 50 * dt                   # a camera, not an aircraft
    assert abs(covered - np.mean(v[:, 3]) * dt) < 0.5   # metres: within GPS noise


def test_all_cameras_recorded_near_one_place():
    """All sample files were recorded around GoPro's Carlsbad (CA) office: every GPS source --
    GPS5 of four cameras, the Karma drone's GPRI and GLPI, the MAX's track -- lies within a
    few km of the others, at latitude ~33 N, longitude ~117 W."""
    points = []
    for name in RAW:
        for strm in streams((DATA / name).read_bytes()):
            for key, cols in (("GPS5", (0, 1)), ("GPRI", (1, 2)), ("GLPI", (1, 2))):
                if key in strm:
                    points.append(scaled(strm, key)[:, cols])
    points = np.concatenate(points)
    assert np.all((32 < points[:, 0]) & (points[:, 0] < 34) & (-118 < points[:, 1]) & (points[:, 1] < -116))
    d = haversine_m(points[:, None, 0], points[:, None, 1], points[None, :, 0], points[None, :, 1])
    assert d.max() < 5_000


# --- the Karma drone's GPS (GPRI): read since these files showed it ------------------------

def test_karma_gps_comes_from_the_drones_gpri():
    """HERO5 on a Karma writes no GPS5; the drone's DEVC carries MAVLink GPS_RAW_INT as GPRI
    (TYPE JlllSSSSBB: time, lat, lon, alt, eph, epv, vel, cog, fix, satellites)."""
    buf = (DATA / "karma.raw").read_bytes()
    drone = next(s for s in streams(buf) if "GPRI" in s)
    assert drone["_dev"].startswith("GoPro Karma") and not any("GPS5" in s for s in streams(buf))
    v = scaled(drone, "GPRI")
    t, lla, fix, dop = (np.concatenate(x) for x in zip(*reader_samples(buf)["gps"]))
    assert np.allclose(lla, v[:, 1:4]) and np.array_equal(fix, v[:, 8]) and np.allclose(dop, v[:, 4])
    tel = gpmf.Telemetry(gps_t=t, gps=lla, fix=fix, dop=dop)
    assert gpmf.good_fixes(tel).all()         # fix 3 (3D), HDOP under 5, 20 satellites
    # the flight controller's fused position (GLPI, another stream) is within a few metres
    glpi = scaled(next(s for s in streams(buf) if "GLPI" in s), "GLPI")
    assert haversine_m(lla[:, 0], lla[:, 1], glpi[:, 1], glpi[:, 2]).max() < 5.0
    poses, warnings = gpmf.gps_poses(tel)
    assert poses is not None and not warnings


def test_the_cameras_own_gps_wins_over_the_drones():
    """A payload with both (HERO5's DEVC with GPS5 and the Karma's DEVC with GPRI): only GPS5."""
    hero5, karma = (DATA / "hero5.raw").read_bytes(), (DATA / "karma.raw").read_bytes()
    drone = karma[gpmf.parse_klv(karma)[0].size * gpmf.parse_klv(karma)[0].repeat + 8:]
    assert gpmf.parse_klv(drone)[0].find("DVNM").data.startswith(b"GoPro Karma")
    got = np.concatenate([g[1] for g in reader_samples(hero5 + drone)["gps"]])
    gps5 = scaled(next(s for s in streams(hero5) if "GPS5" in s), "GPS5")
    assert np.allclose(got, gps5[:, :3])


# --- the MAX's MP4 ------------------------------------------------------------------------

def test_read_telemetry_agrees_with_the_payloads_read_from_the_mp4_tables(max_tel, max_tracks):
    """The gpmd samples found through the MP4 sample tables, each decoded independently, give
    the same GPS, CORI and GYRO values in the same order as read_telemetry (through PyAV)."""
    payloads = max_tracks["gpmd"]["payloads"]
    gps = np.concatenate([scaled(s, "GPS5")[:, :3] for p in payloads for s in streams(p) if "GPS5" in s])
    cori = np.concatenate([scaled(s, "CORI") for p in payloads for s in streams(p) if "CORI" in s])
    gyro = np.concatenate([scaled(s, "GYRO") for p in payloads for s in streams(p) if "GYRO" in s])
    assert np.allclose(max_tel.gps, gps) and np.allclose(max_tel.cori, cori) and np.allclose(max_tel.gyro, gyro)
    fix = np.concatenate([np.full(numbers(s["GPS5"]).shape[0], numbers(s["GPSF"])[0, 0])
                          for p in payloads for s in streams(p) if "GPS5" in s])
    assert np.array_equal(max_tel.fix, fix)


def test_stamps_follow_the_mp4_sample_times(max_tel, max_tracks):
    """Each payload's samples lie within its own sample time (stts) on the video's clock."""
    track = max_tracks["gpmd"]
    video = max_tracks["avc1"]["duration"]
    for t in (max_tel.gps_t, max_tel.cori_t, max_tel.gyro_t):
        assert np.all(np.diff(t) > 0) and t[0] >= 0 and t[-1] < video + 0.1
    k = 0
    for start, dur, p in zip(track["starts"], track["durations"], track["payloads"]):
        n = sum(numbers(s["GPS5"]).shape[0] for s in streams(p) if "GPS5" in s)
        stamps = max_tel.gps_t[k:k + n]
        assert np.all((stamps >= start - 1e-9) & (stamps < start + dur))
        k += n
    assert k == max_tel.gps_t.size


def test_max_gps_track_is_a_walk(max_tel):
    """Good 3D fixes; in local metres a walk: steps under 3 m/s, the path length agrees with
    the receiver's own speed integrated over time, and with haversine distances."""
    ok = gpmf.good_fixes(max_tel)
    assert ok.all() and np.all(max_tel.fix >= 3) and np.all(max_tel.dop < 5)
    poses, warnings = gpmf.gps_poses(max_tel)
    assert poses is not None and not warnings and poses.x[0] == 0 and poses.y[0] == 0
    step = np.hypot(np.diff(poses.x), np.diff(poses.y))
    assert np.all(step / np.diff(poses.t) < 3.0)
    lat, lon = max_tel.gps[:, 0], max_tel.gps[:, 1]
    assert np.allclose(step, haversine_m(lat[:-1], lon[:-1], lat[1:], lon[1:]), atol=0.01)
    assert np.all((-500 < max_tel.gps[:, 2]) & (max_tel.gps[:, 2] < 9000))
    payloads = mp4_tracks(MAX_MP4)["gpmd"]["payloads"]
    speed2d = np.concatenate([scaled(s, "GPS5")[:, 3] for p in payloads for s in streams(p) if "GPS5" in s])
    travelled = np.sum(speed2d[:-1] * np.diff(max_tel.gps_t))
    net = np.hypot(poses.x[-1], poses.y[-1])
    assert net <= step.sum() and 0.8 < step.sum() / travelled < 1.25


def test_max_cori_is_unit_quaternions_and_within_what_the_gyro_turned(max_tel):
    """CORI (SCAL 32767) are unit quaternions. The rotation between two orientations cannot
    exceed the integral of the gyro's rate magnitude over that time (axis order aside)."""
    q = max_tel.cori
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-3)
    rate = np.linalg.norm(max_tel.gyro, axis=1)
    turned = np.concatenate([[0], np.cumsum(rate[:-1] * np.diff(max_tel.gyro_t))])
    for i in range(0, len(q) - 30, 10):
        j = i + 30                                              # about one second apart
        angle = 2 * np.arccos(min(1.0, abs(float(np.dot(q[i], q[j])))))
        integral = np.interp(max_tel.cori_t[j], max_tel.gyro_t, turned) - \
            np.interp(max_tel.cori_t[i], max_tel.gyro_t, turned)
        assert angle <= integral + 0.05


def test_max_headings_are_finite_inside_the_track(max_tel):
    stamps = np.linspace(max_tel.gps_t[0], max_tel.gps_t[-1], 50)
    yaw = gpmf.headings_at(max_tel, stamps)
    assert yaw is not None and yaw.shape == stamps.shape and np.all(np.isfinite(yaw))
    assert np.all((-np.pi <= yaw) & (yaw < np.pi))
    # headings_at interpolates cori_yaw: at the CORI stamps themselves it is cori_yaw
    assert np.allclose(np.angle(np.exp(1j * (gpmf.headings_at(max_tel, max_tel.cori_t)
                                             - gpmf.cori_yaw(max_tel.cori)))), 0, atol=1e-9)
