"""A folder of equirectangular images (png, jpg, jpeg, bmp, tif, tiff) as a recording.

Frames are the image files in natural name order (``img2`` before ``img10``).

Stamps come from an optional ``stamps.csv`` in the folder, in one of two forms:

1. one stamp (seconds) per line, no header, one line per image in name order::

       0.0
       0.5
       1.0

2. a header ``filename,stamp`` and one row per image (any row order)::

       filename,stamp
       frame_000000.png,1692000000.10
       frame_000001.png,1692000000.60

   Every image must have a row and every row must name an image of the folder.

Blank lines are ignored. Stamps must not decrease in name order.

Without stamps.csv, photos that ALL carry an EXIF capture time (DateTimeOriginal,
with SubSecTimeOriginal and OffsetTimeOriginal when present; see ``exif.py``) are
ordered by that time (name order among equal times) and stamped in seconds from the
first photo. Otherwise (any photo without a readable time) the order is the name
order and the stamp of frame ``i`` is ``i * interval`` (interval given when opening,
default 1.0 s).

Positions: when EVERY photo has an EXIF GPS fix, ``FolderSource.poses`` holds them as
``engine.poses.Poses`` on the frames' stamps: metres east (x) and north (y) of the first
photo's fix (``geo.local_metres``), with yaw from GPSImgDirection when every photo has
one. Otherwise ``poses`` is None (no partial tracks). Malformed tags are skipped with a
line in ``FolderSource.warnings``. Headings: when every photo says which way its image
centre looked (``FolderSource.headings()``, for the panorama shift). ``panotopo map`` stores these positions as node ``x``,
``y`` unless ``--poses`` is given, e.g. for five GoPro MAX photos walking 9 m north::

    panotopo map ../shared/data/real/panoramax-gopromax -o gopro.graphml
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional

import cv2
import numpy as np

from ..errors import InputError
from ..frames import Frame, IndexedSource, check_equirectangular, check_equirectangular_size
from ..poses import Poses
from ..validate import frame_size, image_file_size
from .exif import PhotoTags, read_photo_tags
from .geo import heading_to_yaw, local_metres

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
STAMPS_FILE = "stamps.csv"


def natural_key(name: str) -> list:
    """Sort key that orders digit runs by value: img2 < img10."""
    return [(0, int(part), "") if part.isdigit() else (1, 0, part.lower())
            for part in re.split(r"(\d+)", name) if part]


def image_files(folder: Path) -> list[Path]:
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(files, key=lambda p: natural_key(p.name))


def read_stamps_csv(csv_path: Path, names: list[str]) -> np.ndarray:
    """Stamps of the images ``names`` (in that order) from a stamps.csv (see module doc)."""
    where = str(csv_path)
    try:
        lines = [ln.strip() for ln in csv_path.read_text().splitlines()]
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{where}: cannot read ({err})") from None
    lines = [ln for ln in lines if ln]
    if lines and [c.strip().lower() for c in lines[0].split(",")] == ["filename", "stamp"]:
        by_name: dict[str, float] = {}
        for n, line in enumerate(lines[1:], start=2):
            cells = [c.strip() for c in line.split(",")]
            if len(cells) != 2:
                raise InputError(f"{where}: line {n} must be 'filename,stamp', got {line!r}")
            by_name[cells[0]] = _float(cells[1], where, n)
        unknown = sorted(set(by_name) - set(names))
        if unknown:
            raise InputError(f"{where}: names images that are not in the folder: "
                             f"{', '.join(unknown[:3])}")
        missing = [nm for nm in names if nm not in by_name]
        if missing:
            raise InputError(f"{where}: no stamp for {len(missing)} image(s), e.g. {missing[0]}")
        stamps = np.array([by_name[nm] for nm in names], dtype=np.float64)
    else:
        stamps = np.array([_float(ln, where, n) for n, ln in enumerate(lines, start=1)],
                          dtype=np.float64)
        if stamps.size != len(names):
            raise InputError(f"{where}: {stamps.size} stamps for {len(names)} images "
                             f"(one stamp per line, or a 'filename,stamp' header)")
    if np.any(np.diff(stamps) < 0):
        raise InputError(f"{where}: stamps decrease in file name order")
    return stamps


def _float(text: str, where: str, line: int) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: line {line}: {text!r} is not a stamp in seconds") from None
    if not np.isfinite(value):
        raise InputError(f"{where}: line {line}: stamp {text!r} is not finite")
    return value


def gps_poses(tags: list[PhotoTags], stamps: np.ndarray) -> Optional[Poses]:
    """Local metres of the photos' GPS fixes on ``stamps``; None unless every photo has one."""
    if not tags or not all(t.has_fix for t in tags):
        return None
    lat = np.array([t.latitude for t in tags])
    lon = np.array([t.longitude for t in tags])
    x, y = local_metres(lat, lon, float(lat[0]), float(lon[0]))
    yaw = None
    if all(t.direction is not None for t in tags):
        yaw = heading_to_yaw(np.array([t.direction for t in tags]))
    return Poses(t=np.asarray(stamps, dtype=np.float64).copy(), x=x, y=y, yaw=yaw)


@dataclass
class FolderLayout:
    """A photo folder's frame order, stamps and (GPS) positions, from names, stamps.csv and EXIF."""

    files: list[Path]
    stamps: np.ndarray
    poses: Optional[Poses]
    warnings: list[str]
    headings: Optional[np.ndarray] = None   # degrees clockwise of the image centres (photo_headings)
    heading_note: str = ""


def folder_layout(folder: Path, interval: float = 1.0) -> FolderLayout:
    """Order, stamps and positions of the images in ``folder`` (module doc); reads no pixels."""
    files = image_files(folder)
    if not files:
        raise InputError(f"{folder}: folder has no images "
                         f"({', '.join(s[1:] for s in IMAGE_SUFFIXES)})")
    tags = [read_photo_tags(f) for f in files]
    warnings = [w for t in tags for w in t.warnings]
    csv_path = folder / STAMPS_FILE
    if csv_path.exists():
        stamps = read_stamps_csv(csv_path, [p.name for p in files])
    elif all(t.time is not None for t in tags):
        order = sorted(range(len(files)), key=lambda i: tags[i].time)  # stable: name order on ties
        files, tags = [files[i] for i in order], [tags[i] for i in order]
        times = np.array([t.time for t in tags], dtype=np.float64)
        stamps = times - times[0]
    else:
        if interval <= 0:
            raise InputError(f"{folder}: interval must be positive, got {interval}")
        stamps = np.arange(len(files), dtype=np.float64) * float(interval)
        if any(t.time is not None for t in tags):
            warnings.append(f"{folder}: not every image has an EXIF capture time: name order, "
                            f"stamps every {interval:g} s")
    poses = gps_poses(tags, stamps)
    if poses is None and any(t.has_fix for t in tags):
        warnings.append(f"{folder}: not every image has a GPS fix: no positions")
    headings, note = photo_headings(tags)
    return FolderLayout(files, stamps, poses, warnings, headings, note)


def photo_headings(tags: list[PhotoTags]) -> tuple[Optional[np.ndarray], str]:
    """(headings in degrees clockwise, where from) when every photo has one (``PhotoTags.heading``);
    (None, "") otherwise, and when several photos all say the very same heading: GoPro MAX
    writes GPano PoseHeadingDegrees 0.0 on every photo, a placeholder, not a direction."""
    if not tags or any(t.heading is None for t in tags):
        return None, ""
    headings = np.array([t.heading for t in tags], dtype=np.float64)
    if headings.size > 1 and np.all(headings == headings[0]):
        return None, ""
    exif = all(t.direction is not None for t in tags)
    return headings, "EXIF GPSImgDirection" if exif else "EXIF GPSImgDirection / XMP GPano:PoseHeadingDegrees"


class FolderSource(IndexedSource):
    """Image files of a folder, in EXIF time order or natural name order (module doc)."""

    def __init__(self, path: str | Path, interval: float = 1.0) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise InputError(f"{self.path}: no such folder")
        layout = folder_layout(self.path, interval)
        self.files = layout.files
        self._stamps = layout.stamps
        self.poses: Optional[Poses] = layout.poses
        self.warnings: list[str] = layout.warnings
        self._headings = layout.headings
        self.heading_note = layout.heading_note
        first = self._read(0)
        self._resolution = (first.shape[1], first.shape[0])

    def headings(self) -> Optional[np.ndarray]:
        """Headings of the photos (EXIF GPSImgDirection / XMP PoseHeadingDegrees), or None."""
        return None if self._headings is None else self._headings.copy()

    def _read(self, index: int) -> np.ndarray:
        file = self.files[index]
        size = image_file_size(file)  # from the header: refuse a huge image before decoding it
        if size is not None:
            frame_size(*size, str(file))
        rgb = _decode(file, cv2.IMREAD_COLOR)
        check_equirectangular(rgb, str(file))
        return rgb

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        """Sampled frames; with ``max_width``, each image is decoded at 1/2, 1/4 or 1/8 of its
        size where that is still at least ``max_width`` wide (libjpeg scales in the DCT while
        decoding: a 5760x2880 GoPro MAX JPEG took 112 ms in full and 37 ms at a quarter),
        with its header size checked as the full frame is (``Frame.source_width`` set)."""
        if not max_width:
            yield from super().frames(interval)
            return
        for index in self.sample_indices(interval):
            yield self._reduced(int(index), int(max_width))

    def _reduced(self, index: int, max_width: int) -> Frame:
        file = self.files[index]
        size = image_file_size(file)
        factor = 1
        if size is not None:
            frame_size(*size, str(file))   # the limits first, as _read does
            check_equirectangular_size(size[0], size[1], str(file))
            self._check_same_size(file, size)
            while factor < 8 and size[0] // (2 * factor) >= max_width:
                factor *= 2
        if factor == 1:
            return self.frame_at(index)
        flag = {2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4, 8: cv2.IMREAD_REDUCED_COLOR_8}[factor]
        return Frame(index, float(self._stamps[index]), _decode(file, flag), size[0])

    def frame_at(self, index: int) -> Frame:
        if not 0 <= index < len(self.files):
            raise IndexError(f"frame {index} outside 0..{len(self.files) - 1}")
        rgb = self._read(index)
        self._check_same_size(self.files[index], (rgb.shape[1], rgb.shape[0]))
        return Frame(index, float(self._stamps[index]), rgb)

    def _check_same_size(self, file: Path, size: tuple[int, int]) -> None:
        if tuple(size) != self._resolution:
            w, h = self._resolution
            raise InputError(f"{file}: image is {size[0]}x{size[1]}, the folder's first image is {w}x{h}")


def _decode(file: Path, flag: int) -> np.ndarray:
    """RGB of an image file decoded by OpenCV with ``flag`` (full size or reduced)."""
    if file.suffix.lower() == ".png":   # libpng prints its own error line on a damaged file
        from .native_stderr import native_messages_dropped

        with native_messages_dropped():
            bgr = cv2.imread(str(file), flag)
    else:
        bgr = cv2.imread(str(file), flag)
    if bgr is None:
        raise InputError(f"{file}: unreadable or corrupt image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
