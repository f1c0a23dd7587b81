"""What a 360 camera's frames are, and their conversion to equirectangular panoramas.

Projections (``Projection.name``):

- ``equirect``: a 2:1 equirectangular panorama (what the engine works on; no conversion).
- ``dual-fisheye``: two circular fisheye images of back-to-back lenses, side by side in one
  frame (Insta360 One/One X ``.insv``, ROS dual-fisheye drivers) or one per video stream
  (``layout="two-streams"``: newer ``.insv``, or the two files, ``_00_`` and ``_10_``, an
  Insta360 writes at 5.7K: ``insta360_pair``); the lens field of view ``fov`` (degrees) and a
  roll of each lens image about its optical axis (``roll``, degrees, counter-clockwise) are
  options. The lens order and orientation are FFmpeg's ``dfisheye``: the left image is one
  lens, the right one the other, both upright; ``roll=A/B`` says the file has the left image
  turned A degrees and the right one B degrees counter-clockwise (e.g. ``roll=0/180`` for a
  back lens recorded upside down), and the conversion turns them back.
- ``eac``: an equi-angular cubemap. ``layout="gopro"`` is the GoPro MAX ``.360`` layout: two
  video streams of three faces each (stream 0: left, front, right; stream 1: down, back, up,
  rotated as in FFmpeg's ``eac``), the left/right and down/up faces ``extra`` columns wider
  than square (4096 x 1344 at 5.6K: faces 1376, 1344, 1376 wide) because the two lenses'
  pictures overlap there: each such face holds its first half from one lens and its second
  half from the other, ``extra`` columns of the sphere twice around its middle. The
  conversion keeps each lens up to the face's centre line (no blending) and drops the copy.
  ``layout="eac"`` is a plain 3 x 2 EAC frame (FFmpeg's, YouTube's).

``Converter`` does the geometry with FFmpeg's ``v360`` filter (bundled with PyAV): the layout
is assembled in numpy (hstack of two streams, GoPro overlap columns dropped, lens rolls; on
the YUV planes of decoded video frames, on RGB for other readers), then one ``v360`` pass to
equirectangular, then area averaging to the width asked for. A converter holds its filter
graphs: one converter per thread.

``parse_projection`` reads the ``--projection`` option: ``NAME[:key=value,...]`` with keys
``fov`` (dual-fisheye lens field of view), ``roll`` (``A/B``, the two lens rolls) and
``layout``; ``detect_projection`` reads what a video file says about itself.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, replace
from fractions import Fraction
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ..errors import InputError

NAMES = ("equirect", "dual-fisheye", "eac")
LAYOUTS = {"equirect": ("single",), "dual-fisheye": ("side-by-side", "two-streams"), "eac": ("eac", "gopro")}

# Lens field of view used when the file does not say: Insta360 One X/X2/X3 lenses cover about
# 200 degrees (the figure commonly given to FFmpeg's dfisheye for .insv); other dual-fisheye
# cameras (Ricoh Theta, ROS drivers of two 190-degree lenses) about 190.
DEFAULT_FOV = {"insta360": 200.0, "generic": 190.0}
MIN_FOV, MAX_FOV = 180.0, 250.0   # a pair of lenses must cover the sphere; more is not a fisheye
# Shape of one GoPro .360 stream: three faces side by side, 4096 x 1344 (5.6K) or 2272 x 736.
GOPRO_ASPECT = (2.9, 3.2)


@dataclass(frozen=True)
class Projection:
    """How a recording's frames map the sphere (module doc)."""

    name: str = "equirect"
    layout: str = ""                   # "" = the name's first layout
    fov: float = 0.0                   # dual-fisheye: lens field of view, degrees (0 = the camera's default)
    roll: tuple = (0.0, 0.0)           # dual-fisheye: roll of each lens image, degrees
    extra: int = 0                     # eac/gopro: columns each side face is wider than square
    source: str = "default"            # where it came from: "option", "container", "default"

    def __post_init__(self) -> None:
        if self.name not in NAMES:
            raise InputError(f"--projection: unknown projection {self.name!r}; expected one of {', '.join(NAMES)}")
        if not self.layout:
            object.__setattr__(self, "layout", LAYOUTS[self.name][0])
        if self.layout not in LAYOUTS[self.name]:
            raise InputError(f"--projection: {self.name} has no layout {self.layout!r}; expected one of "
                             f"{', '.join(LAYOUTS[self.name])}")
        if self.name == "dual-fisheye" and self.fov:
            if not MIN_FOV <= self.fov <= MAX_FOV:
                raise InputError(f"--projection: fisheye field of view must be {MIN_FOV:g}-{MAX_FOV:g} degrees, "
                                 f"got {self.fov:g}")
        object.__setattr__(self, "roll", tuple(float(r) for r in self.roll))

    @property
    def converts(self) -> bool:
        return self.name != "equirect"

    @property
    def streams(self) -> int:
        """Video streams the frames come from."""
        return 2 if self.layout in ("two-streams", "gopro") else 1

    def as_option(self) -> str:
        """The ``--projection`` text that gives this projection back (``parse_projection``)."""
        parts = [f"layout={self.layout}"]
        if self.fov:
            parts.insert(0, f"fov={self.fov:g}")
        if any(self.roll):
            parts.append("roll=" + "/".join(f"{r:g}" for r in self.roll))
        return f"{self.name}:{','.join(parts)}"

    def as_meta(self) -> dict:
        """What the descriptors' meta records."""
        d = asdict(self)
        d["roll"] = list(self.roll)
        return d


def projection_option(meta: dict) -> Optional[str]:
    """The ``--projection`` text of a descriptors' meta (``Projection.as_meta``), to open the
    recording again as it was described (e.g. a viewer of a bag of fisheyes); None when the
    frames needed no conversion."""
    d = (meta or {}).get("projection") or {}
    if not d or d.get("name", "equirect") == "equirect":
        return None
    return Projection(name=d["name"], layout=d.get("layout", ""), fov=float(d.get("fov") or 0.0),
                      roll=tuple(d.get("roll") or (0.0, 0.0))).as_option()


def parse_projection(text: Optional[str]) -> Optional[Projection]:
    """``--projection NAME[:key=value,...]`` (module doc); None for None or ''."""
    if not text:
        return None
    name, _, rest = str(text).strip().partition(":")
    fields: dict = {"name": name.strip().lower(), "source": "option"}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq:
            raise InputError(f"--projection: {item!r} is not key=value (e.g. dual-fisheye:fov=200)")
        try:
            if key == "fov":
                fields["fov"] = float(value)
            elif key == "roll":
                parts = [float(v) for v in value.split("/")]
                if len(parts) != 2:
                    raise ValueError
                fields["roll"] = tuple(parts)
            elif key == "layout":
                fields["layout"] = value.strip().lower()
            else:
                raise InputError(f"--projection: unknown key {key!r} (fov, roll, layout)")
        except ValueError:
            raise InputError(f"--projection: bad value in {item!r} (fov=DEGREES, roll=A/B, layout=NAME)") from None
    if not all(np.isfinite(v) for v in (fields.get("fov", 0.0), *fields.get("roll", ()))):
        raise InputError("--projection: values must be finite numbers")
    return Projection(**fields)


# --------------------------------------------------------------------------- detection

@dataclass(frozen=True)
class StreamShape:
    width: int
    height: int
    handler: str = ""


def projection_from_streams(shapes: Sequence[StreamShape], suffix: str,
                            given: Optional[Projection] = None, pair: Optional[StreamShape] = None) -> Projection:
    """The projection of a video with these video streams (in order) and file suffix.

    Rules (what cameras write): two video streams of equal size about 3:1 -> GoPro EAC;
    two square streams -> dual fisheye, one lens per stream; ``.insv`` with one 2:1 stream ->
    dual fisheye side by side; else equirectangular. ``pair``: the video stream of the other
    lens's file (Insta360 at 5.7K writes one file per lens, ``insta360_pair``), which makes
    one square stream and its pair a dual fisheye of two streams. A ``given`` projection (the
    option) wins over the file, but keeps the stream layout the file has where the option
    names none.
    """
    video = [s for s in shapes if s.width > 0 and s.height > 0]
    if pair is not None and len(video) == 1:
        video = [video[0], pair]
    insta = suffix.lower() == ".insv"
    two_equal = len(video) >= 2 and (video[0].width, video[0].height) == (video[1].width, video[1].height)
    gopro = two_equal and GOPRO_ASPECT[0] <= video[0].width / video[0].height <= GOPRO_ASPECT[1]
    squares = two_equal and video[0].width == video[0].height
    if given is not None and given.source == "option":
        if given.name == "dual-fisheye" and squares and given.layout == "side-by-side":
            given = replace(given, layout="two-streams")
        if given.name == "eac" and gopro:
            given = replace(given, layout="gopro")
        if given.name == "dual-fisheye" and not given.fov:
            given = replace(given, fov=DEFAULT_FOV["insta360" if insta else "generic"])
        return _with_extra(given, video)
    if gopro:
        return _with_extra(Projection("eac", "gopro", source="container"), video)
    if squares:
        fov = DEFAULT_FOV["insta360" if insta else "generic"]
        return Projection("dual-fisheye", "two-streams", fov=fov, source="container")
    if insta and video and video[0].width == 2 * video[0].height:
        return Projection("dual-fisheye", "side-by-side", fov=DEFAULT_FOV["insta360"], source="container")
    return Projection("equirect", source="default")


def _with_extra(p: Projection, video: Sequence[StreamShape]) -> Projection:
    """GoPro layout: the overlap columns from the stream shape (width = 3 h + 2 extra)."""
    if p.layout != "gopro":
        return p
    if len(video) < 2:
        raise InputError("the GoPro EAC layout needs two video streams")
    w, h = video[0].width, video[0].height
    extra = (w - 3 * h) // 2
    if extra < 0 or (w - 3 * h) % 2 or extra % 2 or extra >= h // 2:
        raise InputError(f"video streams of {w}x{h} are not GoPro EAC strips (3 faces of {h} plus overlap)")
    return replace(p, extra=int(extra))


_INSTA_PAIR = re.compile(r"^(.*_)(00|10)(_\d+\.insv)$", re.IGNORECASE)


def insta360_pair(path: Path) -> Optional[tuple[Path, Path]]:
    """(lens 0 file, lens 1 file) of an Insta360 recording written one file per lens
    (``VID_<date>_<time>_00_<n>.insv`` and ``..._10_<n>.insv``), when both exist; else None."""
    m = _INSTA_PAIR.match(Path(path).name)
    if m is None:
        return None
    files = [Path(path).with_name(f"{m.group(1)}{lens}{m.group(3)}") for lens in ("00", "10")]
    return (files[0], files[1]) if all(f.is_file() for f in files) else None


def lens_inputs(path: Path, p: Projection) -> list[tuple[Path, int]]:
    """(file, video stream number) of each stream the frames of ``p`` come from: the file's
    own streams, or the two files of an Insta360 pair (``insta360_pair``)."""
    if p.streams == 2:
        pair = insta360_pair(path)
        if pair is not None and len(_shapes_of(path)) == 1:
            return [(pair[0], 0), (pair[1], 0)]
        return [(Path(path), 0), (Path(path), 1)]
    return [(Path(path), 0)]


def _shapes_of(path: Path) -> list[StreamShape]:
    import av

    with av.open(str(path)) as container:
        return [StreamShape(int(s.codec_context.width or 0), int(s.codec_context.height or 0),
                            str(s.metadata.get("handler_name", "")).strip())
                for s in container.streams.video]


def detect_projection(path: Path, given: Optional[Projection] = None) -> Projection:
    """``projection_from_streams`` for the file at ``path`` (read with PyAV). A file PyAV
    cannot open is equirectangular as far as this goes (the video reader then says what is
    wrong) unless ``given`` asks for a conversion, which needs PyAV: then InputError."""
    try:
        import av
        import av.error
    except ImportError:
        if given is not None and given.converts:
            raise InputError(f"{path}: converting {given.name} video needs PyAV (pip install av)") from None
        return given or Projection()
    try:
        shapes = _shapes_of(path)
        pair = None
        files = insta360_pair(path)
        if files is not None and len(shapes) == 1:
            others = _shapes_of(files[1] if Path(path).name == files[0].name else files[0])
            if len(others) == 1 and (others[0].width, others[0].height) == (shapes[0].width, shapes[0].height):
                pair = others[0]
    except (av.error.FFmpegError, OSError) as err:
        if given is not None and given.converts:
            raise InputError(f"{path}: unreadable or unsupported video container "
                             f"({getattr(err, 'strerror', None) or err})") from None
        return given or Projection()
    return projection_from_streams(shapes, Path(path).suffix, given, pair)


# Two lens images side by side have a panorama's 2:1 shape; what gives them away is the black
# outside each lens's image circle. Corners: farther than CORNER_RADIUS (in units of the half's
# height) from a half's centre (the image circle's radius is 0.5); the inside: nearer than 0.4.
CORNER_RADIUS = 0.56
CORNER_MAX_MEAN, CORNER_MAX_STD, INSIDE_MIN_MEAN = 16.0, 8.0, 24.0


def looks_like_dual_fisheye(rgb: np.ndarray) -> bool:
    """Whether a 2:1 frame is two fisheye images side by side: in both halves the corners
    outside the image circle are black (brightest channel mean under 16, spread under 8, room
    for codec noise) while the picture inside is not. An equirectangular panorama has sky,
    ceiling or ground there, not four uniform black corners in each half."""
    if rgb.ndim != 3 or rgb.shape[1] != 2 * rgb.shape[0] or rgb.shape[0] < 16:
        return False
    h = rgb.shape[0]
    step = max(1, h // 128)   # a coarse grid is enough, and cheap on 4K frames
    small = rgb[::step, ::step]
    hs = small.shape[0]
    yy, xx = np.mgrid[0:hs, 0:hs]
    r = np.hypot(yy - (hs - 1) / 2.0, xx - (hs - 1) / 2.0) / hs
    corner, inside = r > CORNER_RADIUS, r < 0.4
    for half in (small[:, :hs], small[:, hs:2 * hs]):
        bright = half.max(axis=2).astype(np.float32)
        if not (bright[corner].mean() < CORNER_MAX_MEAN and bright[corner].std() < CORNER_MAX_STD
                and bright[inside].mean() > INSIDE_MIN_MEAN):
            return False
    return True


# --------------------------------------------------------------------------- geometry

def check_shapes(p: Projection, shapes: Sequence[tuple[int, int]]) -> None:
    """InputError unless frames of these (width, height), one per stream, can be ``p``: two
    square lens images side by side (2:1) or one per stream, a 3:2 EAC frame, GoPro strips."""
    w, h = shapes[0]
    if any(tuple(s) != (w, h) for s in shapes[1:]):
        raise InputError(f"{p.name}: its video streams differ in size ({', '.join(f'{a}x{b}' for a, b in shapes)})")
    expected = {("dual-fisheye", "side-by-side"): (w == 2 * h, "two square lens images side by side (2:1)"),
                ("dual-fisheye", "two-streams"): (w == h, "one square lens image per stream"),
                ("eac", "eac"): (2 * w == 3 * h, "a 3:2 frame of six faces")}
    ok, what = expected.get((p.name, p.layout), (True, ""))
    if not ok:
        raise InputError(f"frames of {w}x{h} are not {p.name} ({p.layout}): expected {what}; "
                         f"check --projection")
    if p.layout == "gopro":
        gopro_columns(w, h, p.extra)


def native_size(p: Projection, shapes: Sequence[tuple[int, int]]) -> tuple[int, int]:
    """(width, height) of the equirectangular panorama at the input's own resolution:
    dual fisheye as wide as both lens images together, EAC four faces wide. InputError when
    the shapes cannot be ``p`` (``check_shapes``)."""
    check_shapes(p, shapes)
    w, h = shapes[0]
    if p.name == "dual-fisheye":
        width = 2 * w if p.layout == "two-streams" else w
    elif p.name == "eac":
        face = h if p.layout == "gopro" else h // 2
        width = 4 * face
    else:
        width = w
    width -= width % 2
    return width, width // 2


def gopro_columns(width: int, height: int, extra: int) -> np.ndarray:
    """Columns of one GoPro .360 stream that make its 3 square faces (module doc): each side
    face keeps columns [0, f/2) and [f/2 + extra, f + extra) of its ``f + extra`` stored ones."""
    f = height
    side = f + extra
    if 2 * side + f != width:
        raise InputError(f"video stream of {width}x{height} is not a GoPro EAC strip with {extra} overlap columns")
    half = f // 2
    face_cols = np.concatenate([np.arange(half), np.arange(half + extra, side)])
    return np.concatenate([face_cols, side + np.arange(f), side + f + face_cols]).astype(np.intp)


class Converter:
    """Frames of projection ``p`` (one per stream) -> equirectangular RGB.

    Frames are RGB arrays (any reader) or decoded ``av.VideoFrame`` objects (the video
    reader): those stay in their YUV format up to the small output, the layout assembled by
    FFmpeg's crop / hstack / vstack in the same graph as ``v360`` (numpy only for turned lens
    images), which costs a fraction of converting 5-6K pictures to RGB first. ``out_width``: width of the panorama
    delivered (2:1); None = the native size. ``v360`` renders at most twice that width, then
    area averaging brings it down (a bilinear remap straight to a much smaller size would
    alias). Not thread-safe: one per thread.
    """

    def __init__(self, p: Projection, shapes: Sequence[tuple[int, int]], out_width: Optional[int] = None) -> None:
        if not p.converts:
            raise ValueError("equirectangular frames need no conversion")
        self.p = p
        self.shapes = [tuple(int(v) for v in s) for s in shapes]
        if len(self.shapes) != p.streams:
            raise InputError(f"{p.name} ({p.layout}) needs {p.streams} video stream(s), got {len(self.shapes)}")
        self.native = native_size(p, self.shapes)
        self.out_width = min(self.native[0], int(out_width)) if out_width else self.native[0]
        self.out_width -= self.out_width % 2
        self.render_width = min(self.native[0], 2 * self.out_width)
        self.render_width -= self.render_width % 2
        self._cols: dict = {}
        self._graphs: dict = {}

    def _v360_args(self) -> str:
        w, h = self.render_width, self.render_width // 2
        if self.p.name == "dual-fisheye":
            fov = f"{self.p.fov or DEFAULT_FOV['generic']:g}"
            return f"input=dfisheye:output=e:ih_fov={fov}:iv_fov={fov}:w={w}:h={h}"
        return f"input=eac:output=e:w={w}:h={h}"

    def _gopro_cols(self, scale: int) -> np.ndarray:
        if scale not in self._cols:
            w, h = self.shapes[0]
            if w % scale or h % scale or self.p.extra % scale:
                raise InputError(f"GoPro EAC strips of {w}x{h} cannot be split at chroma resolution")
            self._cols[scale] = gopro_columns(w // scale, h // scale, self.p.extra // scale)
        return self._cols[scale]

    def assemble(self, images: Sequence[np.ndarray], scale: int = 1) -> np.ndarray:
        """The one image ``v360`` reads (layout module doc) from one image per stream: RGB, or
        one plane of YUV (``scale`` 2 for the half-size chroma planes)."""
        if len(images) != self.p.streams:
            raise InputError(f"{self.p.name}: expected {self.p.streams} image(s), got {len(images)}")
        if self.p.layout == "gopro":
            cols = self._gopro_cols(scale)
            return np.vstack([np.take(img, cols, axis=1) for img in images])
        if self.p.name == "dual-fisheye":
            if self.p.layout == "two-streams":
                lenses = list(images)
            else:
                img = images[0]
                half = img.shape[1] // 2
                lenses = [img[:, :half], img[:, half:2 * half]]
            if any(self.p.roll):
                lenses = [_rolled(lens, -r) for lens, r in zip(lenses, self.p.roll)]   # undo the turn
            if self.p.layout == "two-streams" or any(self.p.roll):
                return np.hstack(lenses)
        return images[0]

    def __call__(self, images: Sequence) -> np.ndarray:
        import av

        if images and isinstance(images[0], av.VideoFrame):
            if any(self.p.roll):   # turned lens images: assembled in numpy, plane by plane
                frames = [self._frame_of(list(images))]
            else:
                frames = list(images)
        else:
            frames = [av.VideoFrame.from_ndarray(np.ascontiguousarray(self.assemble(images)), format="rgb24")]
        _, srcs, sink = self._stacked_graph(frames)
        for src, frame in zip(srcs, frames):
            src.push(frame)
        out = sink.pull()
        if self.render_width > self.out_width:
            return out.reformat(width=self.out_width, height=self.out_width // 2, format="rgb24",
                                interpolation="AREA").to_ndarray()
        return out.to_ndarray(format="rgb24")

    def _stacked_graph(self, frames: list):
        """The filter graph for ``frames`` (one per input of the graph): with two, FFmpeg itself
        assembles the layout (crop, hstack, vstack) before ``v360``; with one, it is the picture."""
        key = tuple((f.width, f.height, f.format.name) for f in frames)
        if key in self._graphs:
            return self._graphs[key]
        import av

        g = av.filter.Graph()
        srcs = [g.add_buffer(width=f.width, height=f.height, format=f.format.name, time_base=Fraction(1, 1000))
                for f in frames]
        if len(frames) == 1:
            tail = srcs[0]
        elif self.p.layout == "gopro":
            w, h = frames[0].width, frames[0].height
            f, extra = h, self.p.extra
            side = f + extra
            cuts = [(0, f // 2), (f // 2 + extra, side + f + f // 2), (side + f + f // 2 + extra, w)]
            strips = []
            for src in srcs:   # each strip: its three square faces side by side
                split = g.add("split", str(len(cuts)))
                src.link_to(split)
                stack = g.add("hstack", f"inputs={len(cuts)}")
                for k, (x0, x1) in enumerate(cuts):
                    crop = g.add("crop", f"w={x1 - x0}:h={h}:x={x0}:y=0")
                    split.link_to(crop, k, 0)
                    crop.link_to(stack, 0, k)
                strips.append(stack)
            tail = g.add("vstack", "inputs=2")
            for k, strip in enumerate(strips):
                strip.link_to(tail, 0, k)
        else:
            tail = g.add("hstack", "inputs=2")
            for k, src in enumerate(srcs):
                src.link_to(tail, 0, k)
        v360 = g.add("v360", self._v360_args())
        sink = g.add("buffersink")
        tail.link_to(v360)
        v360.link_to(sink)
        g.configure()
        self._graphs[key] = (g, srcs, sink)
        return self._graphs[key]

    def _frame_of(self, frames: list):
        """The assembled picture of decoded frames, in YUV 4:2:0, by numpy (turned lenses)."""
        import av

        fmt = frames[0].format.name if frames[0].format.name in ("yuv420p", "yuvj420p") else "yuv420p"
        planes = []
        for f in frames:
            arr = f.to_ndarray(format=fmt)
            h, w = arr.shape[0] * 2 // 3, arr.shape[1]
            q = (h // 2) * (w // 2)
            flat = arr[h:].reshape(-1)
            planes.append((arr[:h], flat[:q].reshape(h // 2, w // 2), flat[q:2 * q].reshape(h // 2, w // 2)))
        y = self.assemble([p[0] for p in planes], 1)
        u = self.assemble([p[1] for p in planes], 2)
        v = self.assemble([p[2] for p in planes], 2)
        h, w = y.shape
        packed = np.concatenate([y.reshape(-1), u.reshape(-1), v.reshape(-1)]).reshape(h * 3 // 2, w)
        return av.VideoFrame.from_ndarray(packed, format=fmt)


def _rolled(lens: np.ndarray, degrees: float) -> np.ndarray:
    """A lens image turned ``degrees`` counter-clockwise about its centre (exact for 90s)."""
    quarter = degrees / 90.0
    if float(quarter).is_integer():
        return np.ascontiguousarray(np.rot90(lens, int(quarter) % 4))
    import cv2

    h, w = lens.shape[:2]
    m = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), degrees, 1.0)
    return cv2.warpAffine(lens, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
