"""GoPro's own telemetry (GPMF) from a video's ``gpmd`` data track: GPS, orientation, gyro.

Format (GoPro's open GPMF specification): a stream of KLV items, each an 8-byte header --
FourCC key, one type character, the size of one sample in bytes (uint8) and the sample
count (uint16, big-endian) -- then ``size * repeat`` bytes of big-endian data, padded to a
multiple of 4. Type 0 is a container of nested items. A ``DEVC`` (device) holds ``STRM``
streams; each stream holds sticky descriptors (``SCAL`` divisors, ``TYPE`` of complex
samples, ``GPSF`` fix, ``GPSP`` precision) before its data item. The track is one payload
per packet (about 1 s); samples of a payload are spread evenly over the packet's duration.

Read here: ``GPS5`` (lat, lon degrees, altitude m, 2D and 3D speed; fix ``GPSF`` and
precision ``GPSP`` = DOP x 100 per payload), ``GPS9`` (the same plus days, seconds, DOP and
fix per sample, HERO11 on), ``GPRI`` (a GoPro Karma drone's own GPS, MAVLink ``GPS_RAW_INT``
in the drone's ``DEVC``: time, lat, lon, alt, HDOP, VDOP, speed, course, fix, satellites; used
where the camera wrote no GPS of its own, as a HERO5 on a Karma does), ``CORI`` (camera
orientation quaternions w, x, y, z relative to the orientation at the start), ``GYRO`` (rad/s,
in the camera's own axis order: HERO5 and Fusion name it "Gyroscope (z,x,y)"). A GPS sample
is used when its fix is at least ``MIN_FIX`` (3: a 3D fix) and its DOP below ``MAX_DOP`` (5:
GoPro's own advice is a GPSP under 500); positions are metres east/north of the first used fix
(``engine.sources.geo.local_metres``). Stamps are seconds on the video's clock (0 at its
first frame).

No maintained GPMF parser on PyPI could be used: ``gpmf`` (0.1, 2020) is unmaintained,
``pygpmf-oz`` pulls in geopandas, contextily, pandas and an FFmpeg binary and installs a
top-level ``tests`` package, ``py-gpmf-parser`` is a C++ build; this reader needs ~150 lines.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError

MIN_FIX = 3          # GPSF: 0 none, 2 2D, 3 3D
MAX_DOP = 5.0        # dilution of precision (GPSP / 100); GoPro: under 500 is a good fix
MIN_GOOD_FIXES = 2   # fewer good samples than this: no positions

# type char -> numpy big-endian dtype
_TYPES = {"b": ">i1", "B": ">u1", "c": "S1", "d": ">f8", "f": ">f4", "F": "S4", "j": ">i8", "J": ">u8",
          "l": ">i4", "L": ">u4", "q": ">i4", "Q": ">i8", "s": ">i2", "S": ">u2", "U": "S16"}
# Fixed-point types (GPMF spec): q is Q15.16, Q is Q31.32; stored as integers, scaled here.
_FIXED_POINT = {"q": 2.0 ** 16, "Q": 2.0 ** 32}


@dataclass
class Klv:
    key: str
    type: str             # "\0" for a container
    size: int             # bytes of one sample
    repeat: int           # samples
    data: bytes = b""
    children: list = field(default_factory=list)

    def find(self, key: str) -> Optional["Klv"]:
        return next((c for c in self.children if c.key == key), None)


def parse_klv(buf: bytes, where: str = "GPMF") -> list[Klv]:
    """The KLV items of ``buf`` (containers parsed recursively). InputError on a bad item."""
    items: list[Klv] = []
    pos, end = 0, len(buf)
    while pos + 8 <= end:
        key_raw, type_raw, size, repeat = struct.unpack(">4scBH", buf[pos:pos + 8])
        if key_raw == b"\0\0\0\0":   # padding
            pos += 8
            continue
        length = size * repeat
        data_end = pos + 8 + length
        if data_end > end:
            raise InputError(f"{where}: GPMF item {key_raw!r} runs past its payload ({data_end} > {end} bytes)")
        key = key_raw.decode("latin-1")
        data = buf[pos + 8:data_end]
        item = Klv(key, type_raw.decode("latin-1"), size, repeat, data)
        if type_raw == b"\0":
            item.children = parse_klv(data, where)
        items.append(item)
        pos += 8 + ((length + 3) & ~3)
    return items


def _dtype(item: Klv, complex_type: str = "") -> np.dtype:
    if item.type == "?":
        if not complex_type:
            raise InputError(f"GPMF: {item.key} has complex samples but no TYPE")
        return np.dtype([(f"f{i}", _TYPES[c]) for i, c in enumerate(complex_type)])
    if item.type not in _TYPES:
        raise InputError(f"GPMF: {item.key} has unknown type {item.type!r}")
    return np.dtype(_TYPES[item.type])


def values(item: Klv, complex_type: str = "") -> np.ndarray:
    """Samples of ``item`` as float64, shape (repeat, elements per sample)."""
    dt = _dtype(item, complex_type)
    if item.type == "?":
        if dt.itemsize != item.size:
            raise InputError(f"GPMF: {item.key} TYPE {complex_type!r} is {dt.itemsize} bytes, samples {item.size}")
        rec = np.frombuffer(item.data, dtype=dt, count=item.repeat)
        return np.stack([rec[name].astype(np.float64) / _FIXED_POINT.get(c, 1.0)
                         for name, c in zip(dt.names, complex_type)], axis=1)
    if item.size % dt.itemsize:
        raise InputError(f"GPMF: {item.key} sample of {item.size} bytes is not whole {item.type!r} values")
    per = item.size // dt.itemsize
    v = np.frombuffer(item.data, dtype=dt, count=per * item.repeat).astype(np.float64).reshape(item.repeat, per)
    return v / _FIXED_POINT.get(item.type, 1.0)


def _scaled(item: Klv, scal: Optional[Klv], complex_type: str = "") -> np.ndarray:
    v = values(item, complex_type)
    if scal is not None:
        s = values(scal).ravel()
        s = np.where(s == 0, 1.0, s)
        v = v / (s if s.size in (1, v.shape[1]) else s[0])
    return v


@dataclass
class Telemetry:
    """Samples on the video clock (seconds); empty arrays where the track had none."""

    gps_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gps: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))    # lat, lon, alt
    fix: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dop: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cori_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cori: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))   # w, x, y, z
    gyro_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gyro: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))   # rad/s


def payload_samples(payload: bytes, t0: float, duration: float, out: dict) -> None:
    """Add the samples of one payload (``t0`` .. ``t0 + duration`` s) to ``out`` (lists by key).
    A Karma drone's GPS (``GPRI``) counts only in a payload without the camera's own GPS."""
    camera_gps, drone_gps = False, []
    for devc in parse_klv(payload):
        for strm in (c for c in devc.children if c.key == "STRM"):
            scal, ctype, fix, dop = strm.find("SCAL"), "", None, None
            for item in strm.children:
                if item.key == "TYPE":
                    ctype = item.data.decode("latin-1").rstrip("\0")
                elif item.key == "GPSF":
                    fix = float(values(item).ravel()[0])
                elif item.key == "GPSP":
                    dop = float(values(item).ravel()[0]) / 100.0
            for item in strm.children:
                if item.key not in ("GPS5", "GPS9", "GPRI", "CORI", "GYRO") or item.repeat == 0:
                    continue
                if item.key == "GYRO" and item.type not in _TYPES:   # e.g. compressed ("#"): mapping
                    continue                                         # never uses it, so no reason to refuse
                v = _scaled(item, scal, ctype)
                t = t0 + np.arange(item.repeat) * (duration / item.repeat)
                if item.key == "GPRI":   # time, lat, lon, alt, HDOP, VDOP, speed, course, fix, satellites
                    drone_gps.append((t, v[:, 1:4], v[:, 8], v[:, 4]))
                    continue
                camera_gps |= item.key in ("GPS5", "GPS9")
                if item.key == "GPS5":
                    n = len(v)
                    out["gps"].append((t, v[:, :3], np.full(n, np.nan if fix is None else fix),
                                       np.full(n, np.nan if dop is None else dop)))
                elif item.key == "GPS9":
                    out["gps"].append((t, v[:, :3], v[:, 8], v[:, 7]))
                elif item.key == "CORI":
                    out["cori"].append((t, v[:, :4]))
                else:
                    out["gyro"].append((t, v[:, :3]))
    if not camera_gps:
        out["gps"].extend(drone_gps)


def read_telemetry(path: Path) -> Optional[Telemetry]:
    """The GPMF track of the video at ``path`` (the data stream tagged ``gpmd`` or named
    "GoPro MET"); None when it has none. InputError when the track is malformed. Read once
    per file version (positions, headings and the shift all ask; the result is cached on the
    path, size and modification time)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError:
        return None
    return _read_telemetry(str(p.resolve()), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=8)
def _read_telemetry(path: str, size: int, mtime_ns: int) -> Optional[Telemetry]:
    import av
    import av.error

    try:
        container = av.open(str(path))
    except (av.error.FFmpegError, OSError):
        return None
    try:
        stream = next((s for s in container.streams.data if _is_gpmf(s)), None)
        if stream is None:
            return None
        tb = float(stream.time_base)
        video = container.streams.video[0] if container.streams.video else None
        start = float((video.start_time or 0) * video.time_base) if video is not None and video.time_base else 0.0
        out: dict = {"gps": [], "cori": [], "gyro": []}
        packets = []
        for packet in container.demux(stream):
            if packet.size == 0 or packet.pts is None:
                continue
            packets.append((int(packet.pts), int(packet.duration or 0), bytes(packet)))
    except av.error.FFmpegError as err:
        raise InputError(f"{path}: its GPMF telemetry cannot be read ({err})") from None
    finally:
        container.close()
    packets.sort()
    for k, (pts, dur, data) in enumerate(packets):
        if dur <= 0:   # last packet without a duration: as long as the one before
            dur = (pts - packets[k - 1][0]) if k else int(round(1.0 / tb))
        payload_samples(data, pts * tb - start, dur * tb, out)
    tel = Telemetry()
    if out["gps"]:
        tel.gps_t = np.concatenate([g[0] for g in out["gps"]])
        tel.gps = np.concatenate([g[1] for g in out["gps"]])
        tel.fix = np.concatenate([g[2] for g in out["gps"]])
        tel.dop = np.concatenate([g[3] for g in out["gps"]])
    if out["cori"]:
        tel.cori_t = np.concatenate([c[0] for c in out["cori"]])
        tel.cori = np.concatenate([c[1] for c in out["cori"]])
    if out["gyro"]:
        tel.gyro_t = np.concatenate([g[0] for g in out["gyro"]])
        tel.gyro = np.concatenate([g[1] for g in out["gyro"]])
    return tel


def _is_gpmf(stream) -> bool:
    tag = str(getattr(stream.codec_context, "codec_tag", "") or "") if getattr(stream, "codec_context", None) else ""
    handler = str(stream.metadata.get("handler_name", ""))
    return tag == "gpmd" or "GoPro MET" in handler


def good_fixes(tel: Telemetry, min_fix: int = MIN_FIX, max_dop: float = MAX_DOP) -> np.ndarray:
    """Which GPS samples count: fix >= ``min_fix`` and DOP < ``max_dop``, finite, not (0, 0)."""
    ok = (tel.fix >= min_fix) & (tel.dop < max_dop)
    ok &= np.isfinite(tel.gps[:, :2]).all(axis=1) & ~((tel.gps[:, 0] == 0) & (tel.gps[:, 1] == 0))
    return ok


def gps_poses(tel: Telemetry, min_fix: int = MIN_FIX, max_dop: float = MAX_DOP):
    """(``engine.poses.Poses`` in metres east/north of the first good fix, warnings); (None,
    warnings) when fewer than ``MIN_GOOD_FIXES`` samples count."""
    from ..poses import Poses
    from .geo import local_metres

    n = int(tel.gps_t.size)
    if n == 0:
        return None, []
    ok = good_fixes(tel, min_fix, max_dop)
    warnings = []
    if int(ok.sum()) < n:
        warnings.append(f"GPMF GPS: {n - int(ok.sum())} of {n} samples left out (fix below {min_fix}D "
                        f"or DOP {max_dop:g} and over)")
    t, lat, lon = tel.gps_t[ok], tel.gps[ok, 0], tel.gps[ok, 1]
    order = np.argsort(t, kind="stable")
    t, lat, lon = t[order], lat[order], lon[order]
    keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
    t, lat, lon = t[keep], lat[keep], lon[keep]
    if t.size < MIN_GOOD_FIXES:
        warnings.append("GPMF GPS: too few good fixes for positions")
        return None, warnings
    x, y = local_metres(lat, lon, float(lat[0]), float(lon[0]))
    return Poses(t=t, x=x, y=y), warnings


def cori_yaw(q: np.ndarray) -> np.ndarray:
    """Yaw (radians, about the camera's z axis, right-handed) of CORI quaternions (w, x, y, z):
    the ZYX Euler angle, as GoPro MAX telemetry tools read it. Relative to the start."""
    w, x, y, z = (np.asarray(q, dtype=np.float64)[:, i] for i in range(4))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def headings_at(tel: Telemetry, stamps: np.ndarray) -> Optional[np.ndarray]:
    """The camera's yaw (radians, ``cori_yaw``) at ``stamps`` (video seconds), interpolated on
    the circle; None without CORI samples."""
    if tel.cori_t.size == 0:
        return None
    yaw = np.unwrap(cori_yaw(tel.cori))
    out = np.interp(np.asarray(stamps, dtype=np.float64), tel.cori_t, yaw)
    return (out + np.pi) % (2 * np.pi) - np.pi
