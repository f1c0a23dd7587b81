"""Capture time, GPS fix and heading of a photo from its EXIF and XMP (Pillow, no exiftool).

360 cameras (GoPro MAX, Insta360, Ricoh Theta) and phone photospheres write:

- ``DateTimeOriginal`` ("YYYY:MM:DD HH:MM:SS", local clock), with ``SubSecTimeOriginal``
  (fraction digits) and ``OffsetTimeOriginal`` ("+01:00") when the camera knows them;
- the GPS IFD (tag 0x8825): ``GPSLatitude``/``GPSLongitude`` as degrees, minutes, seconds
  with ``GPSLatitudeRef`` N/S and ``GPSLongitudeRef`` E/W, ``GPSAltitude`` (metres,
  ``GPSAltitudeRef`` 1 = below sea level) and ``GPSImgDirection`` (heading of the image
  centre, degrees clockwise from north; ``GPSImgDirectionRef`` T true or M magnetic);
- XMP ``GPano:ProjectionType`` ("equirectangular" for a full panorama) and
  ``GPano:PoseHeadingDegrees`` (heading of the image centre, degrees clockwise from north).

``read_photo_tags`` never raises for bad tags: a malformed field is left out and a
one-line warning says which and why (the photo itself is still usable).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any, Optional

EXIF_IFD = 0x8769
GPS_IFD = 0x8825
DATETIME_ORIGINAL = 0x9003
OFFSET_TIME_ORIGINAL = 0x9011
SUBSEC_TIME_ORIGINAL = 0x9291
GPS_LATITUDE_REF, GPS_LATITUDE = 1, 2
GPS_LONGITUDE_REF, GPS_LONGITUDE = 3, 4
GPS_ALTITUDE_REF, GPS_ALTITUDE = 5, 6
GPS_IMG_DIRECTION = 17

_PROJECTION = re.compile(rb"GPano:ProjectionType\s*(?:=\s*[\"']([^\"']*)[\"']|>\s*([^<\s]*)\s*<)")
_POSE_HEADING = re.compile(rb"GPano:PoseHeadingDegrees\s*(?:=\s*[\"']([^\"']*)[\"']|>\s*([^<\s]*)\s*<)")


@dataclass(frozen=True)
class PhotoTags:
    """What a photo's EXIF/XMP say; None where absent or malformed."""

    time: Optional[float] = None        # seconds since 1970 (UTC when the offset is known)
    latitude: Optional[float] = None    # degrees, north positive
    longitude: Optional[float] = None   # degrees, east positive
    altitude: Optional[float] = None    # metres above sea level
    direction: Optional[float] = None   # heading, degrees clockwise from north
    projection: Optional[str] = None    # XMP GPano:ProjectionType
    pose_heading: Optional[float] = None  # XMP GPano:PoseHeadingDegrees, degrees clockwise from north
    warnings: tuple[str, ...] = ()

    @property
    def has_fix(self) -> bool:
        return self.latitude is not None and self.longitude is not None

    @property
    def heading(self) -> Optional[float]:
        """Heading of the image centre: GPSImgDirection, else GPano's PoseHeadingDegrees; None
        when the photo has neither. (GoPro MAX writes PoseHeadingDegrees 0.0 on every photo, a
        placeholder beside its GPSImgDirection, so GPSImgDirection comes first.)"""
        return self.direction if self.direction is not None else self.pose_heading


def read_photo_tags(path: str | Path) -> PhotoTags:
    """Tags of the image at ``path`` (see module doc); warnings instead of exceptions."""
    from PIL import Image

    path = Path(path)
    warnings: list[str] = []
    try:
        with Image.open(path) as im:
            exif = im.getexif()
            xmp = im.info.get("xmp")
            sub = _ifd(exif, EXIF_IFD, path, "Exif", warnings)
            gps = _ifd(exif, GPS_IFD, path, "GPS", warnings)
    except Exception as err:  # Pillow raises many kinds for a broken header
        return PhotoTags(warnings=(f"{path.name}: EXIF unreadable ({_short(err)}); ignored",))
    fields: dict[str, Any] = {}
    fields["time"] = _field(path, "DateTimeOriginal", warnings, _time, sub)
    if gps:
        lat = _field(path, "GPSLatitude", warnings, _coordinate, gps, GPS_LATITUDE,
                     GPS_LATITUDE_REF, "NS", 90.0)
        lon = _field(path, "GPSLongitude", warnings, _coordinate, gps, GPS_LONGITUDE,
                     GPS_LONGITUDE_REF, "EW", 180.0)
        if (lat is None) != (lon is None):
            warnings.append(f"{path.name}: GPS has only one of latitude and longitude; ignored")
            lat = lon = None
        fields.update(latitude=lat, longitude=lon)
        fields["altitude"] = _field(path, "GPSAltitude", warnings, _altitude, gps)
        fields["direction"] = _field(path, "GPSImgDirection", warnings, _direction, gps)
    fields["projection"] = _field(path, "GPano:ProjectionType", warnings, _projection, xmp)
    fields["pose_heading"] = _field(path, "GPano:PoseHeadingDegrees", warnings, _pose_heading, xmp)
    return PhotoTags(**fields, warnings=tuple(warnings))


def _short(err: BaseException) -> str:
    return " ".join(str(err).split())[:120] or type(err).__name__


def _ifd(exif, tag: int, path: Path, name: str, warnings: list[str]) -> dict:
    try:
        return dict(exif.get_ifd(tag))
    except Exception as err:
        warnings.append(f"{path.name}: {name} IFD unreadable ({_short(err)}); ignored")
        return {}


def _field(path: Path, name: str, warnings: list[str], parse, *args):
    """``parse(*args)``; a ValueError/TypeError/... becomes a warning and None."""
    try:
        return parse(*args)
    except Exception as err:
        warnings.append(f"{path.name}: {name} malformed ({_short(err)}); ignored")
        return None


def _text(value: Any) -> str:
    if isinstance(value, bytes):
        value = value.decode("ascii", errors="replace")
    return str(value).strip("\x00 ").strip()


def _number(value: Any) -> float:
    number = float(value)  # IFDRational, int, float
    if not math.isfinite(number):
        raise ValueError(f"not a finite number: {value!r}")
    return number


def _time(sub: dict) -> Optional[float]:
    raw = sub.get(DATETIME_ORIGINAL)
    if raw is None:
        return None
    stamp = datetime.strptime(_text(raw), "%Y:%m:%d %H:%M:%S")
    digits = _text(sub.get(SUBSEC_TIME_ORIGINAL, ""))
    fraction = float(f"0.{digits}") if digits.isdigit() else 0.0
    offset = _text(sub.get(OFFSET_TIME_ORIGINAL, ""))
    m = re.fullmatch(r"([+-])(\d\d):(\d\d)", offset)
    tz = timezone.utc
    if m:  # local clock + offset: a true instant, comparable across time zones
        delta = timedelta(hours=int(m.group(2)), minutes=int(m.group(3)))
        tz = timezone(delta if m.group(1) == "+" else -delta)
    return stamp.replace(tzinfo=tz).timestamp() + fraction


def _coordinate(gps: dict, tag: int, ref_tag: int, refs: str, limit: float) -> Optional[float]:
    value = gps.get(tag)
    if value is None:
        return None
    parts = [_number(v) for v in (value if isinstance(value, (tuple, list)) else (value,))]
    if not 1 <= len(parts) <= 3:
        raise ValueError(f"expected degrees, minutes, seconds, got {len(parts)} values")
    degrees = sum(p / 60.0 ** n for n, p in enumerate(parts))
    ref = _text(gps.get(ref_tag, "")).upper()
    if ref not in ("", refs[0], refs[1]):
        raise ValueError(f"reference {ref!r} is not {refs[0]} or {refs[1]}")
    if ref == refs[1]:
        degrees = -degrees
    if abs(degrees) > limit:
        raise ValueError(f"{degrees:.6f} degrees is out of range")
    return degrees


def _altitude(gps: dict) -> Optional[float]:
    value = gps.get(GPS_ALTITUDE)
    if value is None:
        return None
    below = gps.get(GPS_ALTITUDE_REF) in (1, b"\x01")
    return -_number(value) if below else _number(value)


def _direction(gps: dict) -> Optional[float]:
    value = gps.get(GPS_IMG_DIRECTION)
    if value is None:
        return None
    degrees = _number(value)
    if not 0.0 <= degrees <= 360.0:
        raise ValueError(f"{degrees} degrees is outside 0..360")
    return degrees % 360.0


def _projection(xmp: Any) -> Optional[str]:
    if not xmp:
        return None
    if isinstance(xmp, str):
        xmp = xmp.encode("utf-8", errors="replace")
    m = _PROJECTION.search(xmp)
    if m is None:
        return None
    return (m.group(1) or m.group(2) or b"").decode("utf-8", errors="replace") or None


def _pose_heading(xmp: Any) -> Optional[float]:
    if not xmp:
        return None
    if isinstance(xmp, str):
        xmp = xmp.encode("utf-8", errors="replace")
    m = _POSE_HEADING.search(xmp)
    if m is None:
        return None
    degrees = _number((m.group(1) or m.group(2) or b"").decode("ascii", errors="replace"))
    if not -360.0 <= degrees <= 360.0:
        raise ValueError(f"{degrees} degrees is outside -360..360")
    return degrees % 360.0
