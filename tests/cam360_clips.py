"""Test recordings in the layouts 360 cameras write, made from our own panorama with FFmpeg's
``v360`` the other way (equirectangular -> dual fisheye / EAC) and written with PyAV:

- ``write_insv``: an Insta360-style .insv, two fisheyes side by side in one H.264 stream
  (One X) or one fisheye per stream (``two_streams``; X2/X3);
- ``write_gopro_360``: a GoPro MAX-style .360: two HEVC streams of three EAC faces each
  (stream 0: left, front, right; stream 1: down, back, up as FFmpeg's ``eac`` rotates them),
  the side faces ``extra`` columns wider with the lenses' overlap around their centre lines,
  handler names as the camera writes them, and a GPMF ``gpmd`` track (``gpmf_payload``);
- ``gpmf_payload``: one second of GPMF KLV (DEVC / STRM / GPS5 with GPSF, GPSP, SCAL; CORI).

Frame k is the panorama rolled ``ROLL`` columns per frame, so ``panorama(k)`` is the truth
each decoded frame is measured against.
"""

from __future__ import annotations

import struct
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

av = __import__("av")

ROOT = Path(__file__).resolve().parent.parent
W, H = 512, 256          # panorama size (and the converted frames' native size)
FPS = 10
ROLL = 8


def panorama(k: int = 0) -> np.ndarray:
    pano = cv2.imread(str(ROOT / "tests" / "data" / "examplepano_1024.jpg"))[:, :, ::-1]
    pano = cv2.resize(pano, (W, H), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(np.roll(pano, ROLL * k, axis=1))


def v360(rgb: np.ndarray, args: str) -> np.ndarray:
    g = av.filter.Graph()
    src = g.add_buffer(width=rgb.shape[1], height=rgb.shape[0], format="rgb24", time_base=Fraction(1, 1000))
    f = g.add("v360", args)
    sink = g.add("buffersink")
    src.link_to(f)
    f.link_to(sink)
    g.configure()
    src.push(av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24"))
    return sink.pull().to_ndarray(format="rgb24")


def dual_fisheye(rgb: np.ndarray, fov: float, lens: int) -> np.ndarray:
    """Two ``lens`` x ``lens`` fisheye images side by side (FFmpeg's dfisheye), black outside
    each lens's image circle as a camera's sensor sees it."""
    out = v360(rgb, f"input=e:output=dfisheye:h_fov={fov:g}:v_fov={fov:g}:w={2 * lens}:h={lens}")
    yy, xx = np.mgrid[0:lens, 0:lens]
    outside = np.hypot(yy - (lens - 1) / 2.0, xx - (lens - 1) / 2.0) > lens / 2.0
    out[:, :lens][outside] = 0
    out[:, lens:][outside] = 0
    return out


def gopro_strips(rgb: np.ndarray, face: int, extra: int) -> tuple[np.ndarray, np.ndarray]:
    """The two GoPro .360 strips of a panorama (module doc)."""
    eac = v360(rgb, f"input=e:output=eac:w={3 * face}:h={2 * face}")
    half = face // 2

    def widen(f: np.ndarray) -> np.ndarray:   # lens A up to centre + extra/2, lens B from centre - extra/2
        return np.hstack([f[:, :half + extra // 2], f[:, half - extra // 2:]])

    strips = []
    for row in (eac[:face], eac[face:]):
        a, b, c = row[:, :face], row[:, face:2 * face], row[:, 2 * face:]
        strips.append(np.ascontiguousarray(np.hstack([widen(a), b, widen(c)])))
    return strips[0], strips[1]


def _video_stream(out, codec: str, w: int, h: int, gop: int, handler: str = ""):
    s = out.add_stream(codec, rate=FPS)
    s.width, s.height, s.pix_fmt = w, h, "yuv420p"
    if codec == "libx265":
        s.options = {"x265-params": f"log-level=error:keyint={gop}:min-keyint={gop}:scenecut=0:bframes=2",
                     "preset": "ultrafast", "crf": "18"}
    else:
        s.options = {"preset": "veryfast", "crf": "16", "x264-params": f"keyint={gop}:min-keyint={gop}:scenecut=0"}
    if handler:
        s.metadata["handler_name"] = handler
    return s


def _encode(out, stream, rgb: np.ndarray, k: int) -> None:
    frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
    frame.pts = k
    for packet in stream.encode(frame):
        out.mux(packet)


def _flush(out, streams) -> None:
    for s in streams:
        for packet in s.encode(None):
            out.mux(packet)


def write_insv(path: Path, frames: int = 20, fov: float = 200.0, lens: int = 256, two_streams: bool = False,
               gop: int = FPS, turns: tuple = (0, 0)) -> Path:
    """``turns``: quarter turns (counter-clockwise) of the left and right lens images."""
    with av.open(str(path), "w", format="mp4") as out:
        if two_streams:
            streams = [_video_stream(out, "libx264", lens, lens, gop) for _ in range(2)]
        else:
            streams = [_video_stream(out, "libx264", 2 * lens, lens, gop)]
        for k in range(frames):
            dfe = dual_fisheye(panorama(k), fov, lens)
            dfe = np.hstack([np.rot90(dfe[:, :lens], turns[0]), np.rot90(dfe[:, lens:], turns[1])])
            parts = [dfe[:, :lens], dfe[:, lens:]] if two_streams else [dfe]
            for s, part in zip(streams, parts):
                _encode(out, s, np.ascontiguousarray(part), k)
        _flush(out, streams)
    return path


def write_gopro_360(path: Path, frames: int = 20, face: int = 128, extra: int = 4, gop: int = FPS,
                    gps: list | None = None, cori_yaw_deg_per_s: float = 0.0) -> Path:
    """``gps``: one GPS sample per frame, (lat, lon, alt, fix, precision x100), written one
    payload per second with the GPSF/GPSP of its first sample; None: no GPMF track.
    CORI turns about z at ``cori_yaw_deg_per_s``, one sample per frame."""
    with av.open(str(path), "w", format="mp4") as out:
        s0 = _video_stream(out, "libx265", 3 * face + 2 * extra, face, gop, "GoPro H.265")
        data = None
        if gps is not None:
            data = out.add_data_stream(codec_name="bin_data")
            data.time_base = Fraction(1, 1000)
            data.metadata["handler_name"] = "GoPro MET"
        s1 = _video_stream(out, "libx265", 3 * face + 2 * extra, face, gop, "GoPro H.265")
        for k in range(frames):
            top, bottom = gopro_strips(panorama(k), face, extra)
            _encode(out, s0, top, k)
            _encode(out, s1, bottom, k)
            if data is not None and k % FPS == 0 and gps[k:k + FPS]:
                sec = k // FPS
                fixes = gps[k:k + FPS]
                payload = gpmf_payload(fixes, cori_yaw_deg=[cori_yaw_deg_per_s * (k + j) / FPS
                                                            for j in range(len(fixes))])
                packet = av.Packet(payload)
                packet.stream = data
                packet.pts = packet.dts = sec * 1000
                packet.duration = round(1000 * len(fixes) / FPS)
                packet.time_base = data.time_base
                out.mux(packet)
        _flush(out, [s0, s1])
    return path


# ----------------------------------------------------------------------------- GPMF KLV

def klv(key: str, type_char: str, size: int, repeat: int, data: bytes) -> bytes:
    head = struct.pack(">4scBH", key.encode("latin-1"), type_char.encode("latin-1") if type_char else b"\0",
                       size, repeat)
    return head + data + b"\0" * ((-len(data)) % 4)


def nest(key: str, *children: bytes) -> bytes:
    body = b"".join(children)
    return klv(key, "", 1, len(body), body) if len(body) < 65536 else klv(key, "", 4, len(body) // 4, body)


def gpmf_payload(fixes: list, cori_yaw_deg: list | None = None, gps9: bool = False) -> bytes:
    """One payload: GPS samples ``fixes`` = [(lat, lon, alt, fix, precision x100), ...] (GPS5
    with one GPSF/GPSP for the payload, taken from the first sample; or GPS9 per sample), and
    CORI quaternions of a turn about z by ``cori_yaw_deg``."""
    streams = []
    if gps9:
        scal = [10_000_000, 10_000_000, 1000, 1000, 100, 1, 1000, 100, 1]
        rows = b"".join(struct.pack(">lllllllHH", round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 0, 0,
                                    9000, 0, int(p), int(f)) for lat, lon, alt, f, p in fixes)
        streams.append(nest("STRM", klv("STNM", "c", 1, 4, b"GPS9"),
                            klv("SCAL", "l", 4, len(scal), struct.pack(f">{len(scal)}l", *scal)),
                            klv("TYPE", "c", 1, 9, b"lllllllSS"),
                            klv("GPS9", "?", 32, len(fixes), rows)))
    else:
        scal = [10_000_000, 10_000_000, 1000, 1000, 100]
        rows = b"".join(struct.pack(">5l", round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 0, 0)
                        for lat, lon, alt, _, _ in fixes)
        streams.append(nest("STRM", klv("STNM", "c", 1, 4, b"GPS5"),
                            klv("GPSF", "L", 4, 1, struct.pack(">L", int(fixes[0][3]))),
                            klv("GPSP", "S", 2, 1, struct.pack(">H", int(fixes[0][4]))),
                            klv("SCAL", "l", 4, 5, struct.pack(">5l", *scal)),
                            klv("GPS5", "l", 20, len(fixes), rows)))
    if cori_yaw_deg:
        q = b"".join(struct.pack(">4h", round(32767 * np.cos(np.radians(a) / 2)), 0, 0,
                                 round(32767 * np.sin(np.radians(a) / 2))) for a in cori_yaw_deg)
        streams.append(nest("STRM", klv("SCAL", "s", 2, 1, struct.pack(">h", 32767)),
                            klv("CORI", "s", 8, len(cori_yaw_deg), q)))
    return nest("DEVC", klv("DVID", "L", 4, 1, struct.pack(">L", 1)), klv("DVNM", "c", 1, 8, b"GoProMAX"),
                *streams)


def write_insv_pair(folder: Path, frames: int = 20, fov: float = 200.0, lens: int = 256,
                    gop: int = FPS) -> tuple[Path, Path]:
    """An Insta360 5.7K-style recording: one file per lens, ``VID_..._00_n.insv`` (left image of
    FFmpeg's dfisheye) and ``VID_..._10_n.insv`` (right), one square H.264 stream each."""
    paths = tuple(folder / f"VID_20260101_120000_{lens_id}_001.insv" for lens_id in ("00", "10"))
    outs = [av.open(str(p), "w", format="mp4") for p in paths]
    try:
        streams = [_video_stream(out, "libx264", lens, lens, gop) for out in outs]
        for k in range(frames):
            dfe = dual_fisheye(panorama(k), fov, lens)
            for out, s, part in zip(outs, streams, (dfe[:, :lens], dfe[:, lens:])):
                _encode(out, s, np.ascontiguousarray(part), k)
        for out, s in zip(outs, streams):
            _flush(out, [s])
    finally:
        for out in outs:
            out.close()
    return paths
