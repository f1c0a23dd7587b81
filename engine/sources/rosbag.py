"""ROS1 .bag and ROS2 bags (directory, bare .db3, bare .mcap) as frame sources.

Image topics are ``sensor_msgs/msg/Image`` (rgb8, bgr8, mono8, mono16, bayer_*,
... anything rosbags-image converts; ``16UC1`` and ``8UC1`` are read as mono16 and
mono8) and ``sensor_msgs/msg/CompressedImage``. Type names are matched in either
spelling, ``sensor_msgs/Image`` (ROS1) or ``sensor_msgs/msg/Image`` (ROS2).
Frames come out RGB uint8; grey images are repeated over three channels and
16-bit images are scaled linearly from the full 16-bit range, value * 255 / 65535
(so a 16UC1 depth image in millimetres up to 10 m comes out dark, at most 39).
Which bags other tools write are read is said in ``bag_reader.py``.

A frame's stamp is its header stamp (``sec + nanosec * 1e-9``, ROS time), or its
log time when the header stamp is zero. Opening a bag reads every message of the
topic once without deserialising it (the header stamp sits at a fixed place in
the serialised bytes) and keeps only (log time, rank) per frame, so memory stays
small for big bags; ``frame_at`` re-reads one message through a one-nanosecond
time window.
"""

from __future__ import annotations

import dataclasses
import io
import struct
import threading
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence

import cv2
import numpy as np

from ..errors import InputError
from ..frames import Frame, IndexedSource, check_equirectangular, sample_indices
from ..validate import frame_size, image_file_size
from .bag_reader import BagFormatError, BagReader, open_reader
from .orientation import POSE_TYPES, candidate_topics, headings_at, orientation_topics, read_yaw

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
ROS2_STORAGE_SUFFIXES = (".db3", ".mcap")
# Storage files of a bag recorded with --compression-mode file (only metadata.yaml says so).
ROS2_PACKED_SUFFIXES = (".db3.zstd", ".mcap.zstd")


# --- opening bags and choosing topics -------------------------------------------


def is_ros2_bag_dir(path: Path) -> bool:
    """A directory holding a ROS2 bag (metadata.yaml or storage files)."""
    return path.is_dir() and (
        (path / "metadata.yaml").exists()
        or any(p.suffix in ROS2_STORAGE_SUFFIXES or p.name.endswith(ROS2_PACKED_SUFFIXES)
               for p in path.iterdir())
    )


def _reader_path(path: Path) -> Path:
    """The path rosbags should open for ``path``.

    rosbags opens a ROS2 directory only through its metadata.yaml; a directory
    without one but with a single .db3/.mcap file is opened as that bare file.
    """
    if not path.exists():
        raise InputError(f"{path}: no such file or directory")
    if path.is_dir() and not (path / "metadata.yaml").exists():
        files = sorted(p for p in path.iterdir() if p.suffix in ROS2_STORAGE_SUFFIXES)
        packed = sorted(p for p in path.iterdir() if p.name.endswith(ROS2_PACKED_SUFFIXES))
        if not files and packed:
            raise InputError(f"{path}: a ROS2 bag compressed whole (--compression-mode file) without "
                             f"its metadata.yaml; decompress it first with 'zstd -d {packed[0]}'")
        if len(files) != 1:
            raise InputError(
                f"{path}: not a ROS2 bag (no metadata.yaml and "
                f"{len(files)} .db3/.mcap files instead of one)"
            )
        return files[0]
    return path


def open_bag(path: Path) -> BagReader:
    """An open ``bag_reader.BagReader``; InputError when the bag is unreadable."""
    target = _reader_path(Path(path))
    if target.is_file() and target.suffix not in (".bag",) + ROS2_STORAGE_SUFFIXES:
        raise InputError(f"{path}: not a ROS bag (expected .bag, .db3, .mcap or a bag directory)")
    try:
        reader = open_reader(target)
    except BagFormatError as err:
        raise InputError(f"{path}: {err}") from None
    except Exception as err:  # rosbags and mcap raise many types for corrupt files
        raise InputError(f"{path}: unreadable ROS bag ({_one_line(err)}); {recovery_hint(Path(path))}") from None
    return reader


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def _topics(reader: Any, msgtypes: Sequence[str]) -> list[tuple[str, str, int]]:
    counts: dict[tuple[str, str], int] = {}
    for c in reader.connections:
        if c.msgtype in msgtypes:
            counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
    return sorted((t, m, n) for (t, m), n in counts.items())


def list_image_topics(path: str | Path) -> list[tuple[str, str, int]]:
    """(topic, msgtype, message count) of every image topic in the bag, by topic name."""
    reader = open_bag(Path(path))
    try:
        return _topics(reader, IMAGE_TYPES)
    finally:
        reader.close()


def list_pose_topics(path: str | Path) -> list[tuple[str, str, int]]:
    """(topic, msgtype, message count) of every Odometry/PoseStamped topic in the bag."""
    reader = open_bag(Path(path))
    try:
        return _topics(reader, POSE_TYPES)
    finally:
        reader.close()


def choose_topic(reader: Any, path: Path, topic: Optional[str],
                 msgtypes: Sequence[str], kind: str) -> tuple[str, list[Any]]:
    """The topic to read and its connections; InputError when none or ambiguous."""
    available = _topics(reader, msgtypes)
    names = sorted({t for t, _, _ in available})
    if topic is None:
        if not names:
            everything = sorted({c.topic for c in reader.connections})
            raise InputError(f"{path}: no {kind} topic in this bag "
                             f"(topics: {', '.join(everything) or 'none'})")
        if len(names) > 1:
            raise InputError(f"{path}: several {kind} topics, choose one with --topic: "
                             f"{', '.join(names)}")
        topic = names[0]
    elif topic not in names:
        raise InputError(f"{path}: no {kind} topic {topic!r}; available {kind} topics: "
                         f"{', '.join(names) or 'none'}")
    return topic, [c for c in reader.connections if c.topic == topic and c.msgtype in msgtypes]


def header_stamp_ns(raw: bytes | memoryview, ros2: bool) -> int:
    """Header stamp of a serialised message that starts with std_msgs/Header.

    ROS1: uint32 seq, uint32 sec, uint32 nsec (little endian).
    ROS2 CDR: 4-byte encapsulation (byte 1 odd = little endian), int32 sec, uint32 nanosec.
    Both put the stamp at bytes 4..12.
    """
    endian = "<" if (not ros2 or raw[1] & 1) else ">"
    sec, nsec = struct.unpack_from(endian + ("iI" if ros2 else "II"), raw, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


def message_stamp(msg: Any, log_ns: int) -> float:
    """Header stamp in seconds, or the log time when the header stamp is zero."""
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return (ns if ns else log_ns) * 1e-9


# --- image conversion -----------------------------------------------------------


def message_to_rgb(msg: Any, msgtype: str) -> np.ndarray:
    """RGB uint8 H x W x 3 from an Image or CompressedImage message (raises ValueError)."""
    from rosbags.image import ImageError, compressed_image_to_cvimage, message_to_cvimage

    try:
        if msgtype == "sensor_msgs/msg/CompressedImage":
            # Decode without a target colour space: rosbags-image assumes colour input,
            # grey JPEG/PNG would fail its bgr8 conversion.
            img = compressed_image_to_cvimage(msg)
            if img is None:
                raise ValueError("not a decodable JPEG/PNG image")
            if img.dtype == np.uint16:
                img = (img.astype(np.float32) * (255.0 / 65535.0) + 0.5).astype(np.uint8)
            if img.ndim == 2:
                return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
            if img.shape[2] == 4:
                return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
            return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        rgb = message_to_cvimage(unpadded(as_named_encoding(msg)), "rgb8")
        return np.ascontiguousarray(rgb, dtype=np.uint8)
    except AssertionError:  # rosbags-image asserts on undecodable compressed data
        raise ValueError("not a decodable JPEG/PNG image") from None
    except (ImageError, cv2.error, TypeError) as err:
        if msgtype != "sensor_msgs/msg/CompressedImage" and "not supported" in str(err):
            # e.g. a 32FC1 depth image: no picture to place-recognise without a choice of scale
            raise ValueError(f"{_one_line(err)}; panotopo reads colour, mono8/mono16 (8UC1/16UC1) "
                             f"and bayer images: republish or convert the topic to one of those") from None
        raise ValueError(_one_line(err)) from None


# OpenCV-style single-channel encodings that mean the same pixels as a named grey one.
GREY_ALIASES = {"16UC1": "mono16", "8UC1": "mono8"}


def as_named_encoding(msg: Any) -> Any:
    """``msg`` with a 16UC1 / 8UC1 encoding renamed mono16 / mono8 (same bytes, same scaling)."""
    alias = GREY_ALIASES.get(str(msg.encoding))
    return msg if alias is None else dataclasses.replace(msg, encoding=alias)


def unpadded(msg: Any) -> Any:
    """An Image message whose rows are exactly width x pixel bytes long.

    ``step`` is the length of a row in bytes; drivers pad rows to an alignment (e.g. 64
    bytes), and rosbags-image reads the data as if there were no padding, which shears
    the picture. Rows are taken ``step`` bytes apart and their first width x channels x
    bytes-per-channel bytes kept. A step shorter than a row, or data shorter than the
    rows it announces, is refused (ValueError)."""
    from rosbags.image.image import to_cvtype

    _, _, typestr, channels = to_cvtype(msg.encoding)
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    row = width * channels * np.dtype(typestr).itemsize
    rows = height * 3 // 2 if msg.encoding in ("nv12", "nv21") else height  # + chroma rows
    data = np.frombuffer(msg.data, dtype=np.uint8) if not isinstance(msg.data, np.ndarray) \
        else msg.data.view(np.uint8).reshape(-1)
    if step < row:
        raise ValueError(f"row step of {step} bytes is shorter than a row of {width} {msg.encoding} "
                         f"pixels ({row} bytes)")
    if rows and data.size < step * (rows - 1) + row:
        raise ValueError(f"{data.size} bytes of data for {rows} rows of {step} bytes")
    if step == row:
        return msg
    packed = np.lib.stride_tricks.as_strided(data, shape=(rows, row), strides=(step, 1))
    return dataclasses.replace(msg, data=np.ascontiguousarray(packed).reshape(-1), step=row)


def message_size(msg: Any, msgtype: str) -> Optional[tuple[int, int]]:
    """(width, height) announced by a message, read before decoding: the Image fields,
    or a CompressedImage's JPEG/PNG header (None when the header cannot be read)."""
    if msgtype != "sensor_msgs/msg/CompressedImage":
        return int(msg.width), int(msg.height)
    return image_file_size(io.BytesIO(bytes(msg.data)))


def recovery_hint(path: Path) -> str:
    """How to rebuild the index of a bag that was cut short (a recorder killed mid-write)."""
    target = path
    if path.is_dir():
        storage = sorted(p for p in path.iterdir() if p.suffix in ROS2_STORAGE_SUFFIXES)
        target = storage[0] if storage else path
    if target.suffix == ".bag":
        return f"if the recording was cut short, 'rosbag reindex {path}' may recover it"
    if target.suffix == ".mcap":
        return f"if the recording was cut short, 'mcap recover {target} -o recovered.mcap' may recover it"
    return f"if the recording was cut short, 'ros2 bag reindex {path}' may recover it"


# --- the frame source -----------------------------------------------------------


class BagSource(IndexedSource):
    """Frames of one image topic of a ROS1 or ROS2 bag.

    ``headings()`` come from the bag's orientation topic (``orientation.py``: Odometry before
    PoseStamped / PoseWithCovarianceStamped before Imu), or ``heading_topic`` when given;
    ``heading_note`` says which, or why none.
    """

    def __init__(self, path: str | Path, topic: Optional[str] = None,
                 heading_topic: Optional[str] = None) -> None:
        self.path = Path(path)
        self._heading_topic = heading_topic
        self._headings: Optional[tuple] = None   # (array or None,) once read
        self._reader = open_bag(self.path)
        self._lock = threading.Lock()  # frame_at may be called from several threads
        try:
            self.topic, self._connections = choose_topic(
                self._reader, self.path, topic, IMAGE_TYPES, "image")
            self._index_messages()
            first = self.frame_at(0)
        except BaseException:
            self._reader.close()
            raise
        h, w = first.rgb.shape[:2]
        self._resolution = (w, h)

    def headings(self) -> Optional[np.ndarray]:
        """Headings (degrees clockwise) of the frames from the bag's orientation topic, or None."""
        with self._lock:
            if self._headings is None:
                self._headings = (self._read_headings(),)
            return self._headings[0]

    def _read_headings(self) -> Optional[np.ndarray]:
        reader = open_bag(self.path)
        notes: list[str] = []
        try:
            if self._heading_topic is not None:
                topics = orientation_topics(reader)
                if self._heading_topic not in topics:
                    raise InputError(f"{self.path}: no orientation topic {self._heading_topic!r}; "
                                     f"orientation topics: {', '.join(topics) or 'none'}")
                candidates, ambiguous = [self._heading_topic], ""
            else:
                candidates, ambiguous = candidate_topics(reader)
            for topic in candidates:
                found = self._headings_of(reader, topic, notes)
                if found is not None:
                    self.heading_note = notes[-1]
                    return found
        finally:
            reader.close()
        self.heading_note = "; ".join(notes + ([ambiguous] if ambiguous else []))
        return None

    def _headings_of(self, reader: Any, topic: str, notes: list[str]) -> Optional[np.ndarray]:
        """Headings at the frames from ``topic``, or None with the reason added to ``notes``."""
        try:
            t, yaw, msgtype = read_yaw(reader, topic)
        except Exception as err:  # the images are fine: the shift falls back to the image
            notes.append(f"{topic} unreadable ({_one_line(err)})")
            return None
        if yaw.size > 1 and np.all(yaw == yaw[0]):
            # GPS-only odometry and some drivers fill the orientation with one value (the
            # identity quaternion) on every message: a placeholder, not a direction
            notes.append(f"{topic} ({msgtype}) has one orientation on every message")
            return None
        found = headings_at(t, yaw, self._stamps)
        notes.append(f"{topic} ({msgtype})" if found is not None
                     else f"{topic} ({msgtype}) does not cover every frame")
        return found

    def _index_messages(self) -> None:
        """One pass over the topic: log time, rank among equal log times, stamp."""
        log_ns: list[int] = []
        ranks: list[int] = []
        stamps_ns: list[int] = []
        try:
            for _, t, raw in self._reader.messages(connections=self._connections):
                ranks.append(ranks[-1] + 1 if log_ns and log_ns[-1] == t else 0)
                log_ns.append(t)
                stamp = header_stamp_ns(raw, self._reader.is2)
                stamps_ns.append(stamp if stamp else t)
        except (struct.error, IndexError):
            raise InputError(f"{self.path}: a message on {self.topic} is truncated; "
                             f"{recovery_hint(self.path)}") from None
        except Exception as err:
            raise InputError(f"{self.path}: cannot read {self.topic} ({_one_line(err)}); "
                             f"{recovery_hint(self.path)}") from None
        if not log_ns:
            raise InputError(f"{self.path}: image topic {self.topic} has no messages")
        # Frames are ordered by stamp; the stable sort keeps bag order for equal stamps.
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        self._order = np.argsort(stamps, kind="stable")  # frame index -> position in bag
        self._log_ns = np.asarray(log_ns, dtype=np.int64)[self._order]
        self._rank = np.asarray(ranks, dtype=np.int64)[self._order]
        self._stamps = stamps[self._order].astype(np.float64) * 1e-9
        self._in_bag_order = bool(np.all(self._order == np.arange(self._order.size)))

    def frame_at(self, index: int) -> Frame:
        if not 0 <= index < self.frame_count:
            raise IndexError(f"frame {index} outside 0..{self.frame_count - 1}")
        t = int(self._log_ns[index])
        with self._lock:
            try:
                window = self._reader.messages(connections=self._connections, start=t, stop=t + 1)
                for rank, (conn, _, raw) in enumerate(window):
                    if rank == self._rank[index]:
                        return self._decode(conn, raw, index)
            except InputError:
                raise
            except Exception as err:
                raise InputError(f"{self.path}: cannot read frame {index} of {self.topic} "
                                 f"({_one_line(err)})") from None
        raise InputError(f"{self.path}: frame {index} of {self.topic} vanished from the bag")

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        """Sampled frames in one forward pass over the bag (own reader, so that
        ``frame_at`` stays usable meanwhile); only the sampled ones are decoded.
        Full size whatever ``max_width`` (decoding is not where a bag's time goes)."""
        wanted = sample_indices(self._stamps, interval)
        if not self._in_bag_order:
            yield from super().frames(interval)
            return
        wanted_set = set(int(i) for i in wanted)
        reader = open_bag(self.path)
        try:
            conns = [c for c in reader.connections if c.topic == self.topic
                     and c.msgtype in IMAGE_TYPES]
            left = len(wanted_set)
            for position, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
                if position in wanted_set:
                    yield self._decode(conn, raw, position, reader)
                    left -= 1
                    if left == 0:
                        break
        finally:
            reader.close()

    def _decode(self, conn: Any, raw: bytes, index: int, reader: Any = None) -> Frame:
        reader = reader or self._reader
        where = f"{self.path}: frame {index} of {self.topic}"
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as err:
            raise InputError(f"{where} cannot be deserialised ({_one_line(err)})") from None
        size = message_size(msg, conn.msgtype)
        if size is not None:  # before decoding: a huge frame is refused, not allocated
            frame_size(*size, where)
        try:
            rgb = message_to_rgb(msg, conn.msgtype)
        except ValueError as err:
            raise InputError(f"{where} is corrupt or unsupported ({err})") from None
        check_equirectangular(rgb, where)
        return Frame(index=index, stamp=float(self._stamps[index]), rgb=rgb)

    def close(self) -> None:
        with self._lock:
            if self._reader is not None:
                self._reader.close()
