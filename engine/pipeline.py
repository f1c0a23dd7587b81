"""One run of the method: recording -> descriptors -> nodes -> loops -> TopoMap.

Two plain functions, called the same way by the CLI, the GUI worker and the tests:
``describe`` is the expensive part (cached on disk); ``build_map`` is cheap and is
re-run whenever a node or loop parameter changes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Iterable, Iterator, Optional, Sequence

import numpy as np

from . import descriptors as descriptor_registry
from .descriptors.base import Descriptors
from .errors import InputError
from .frames import Frame, FrameSource
from .sources import open_source
from .params import MapParams
from .progress import CancelToken, Progress, check


@dataclass(frozen=True)
class DescribeSettings:
    descriptor: str = descriptor_registry.DEFAULT_DESCRIPTOR
    interval: float = 1.0
    topic: Optional[str] = None
    shift: bool = True
    options: dict = field(default_factory=dict)  # passed to the descriptor model
    skip_bad_frames: bool = False  # skip undecodable frames (listed in meta "skipped_frames")
    projection: Optional[str] = None  # --projection (engine.sources.projection); None: what the file says
    sampling: str = "interval"     # "interval": every ``interval`` s; "keyframes": a video's key frames only

    def as_dict(self) -> dict:
        return asdict(self)


def method_settings(params: MapParams, settings: Optional[DescribeSettings] = None) -> DescribeSettings:
    """``settings`` as ``params.method`` describes: its panorama shift, and its describe options
    (``engine.params.METHOD_DESCRIBE_OPTIONS``) for the keys ``settings.descriptor`` has that
    ``settings.options`` does not already name (an option the user gave wins)."""
    from .validate import ALLOWED_OPTIONS

    settings = settings or DescribeSettings()
    allowed = ALLOWED_OPTIONS.get(settings.descriptor, {})
    filled = {k: v for k, v in params.describe_options.items() if k in allowed and k not in settings.options}
    return replace(settings, shift=params.uses_shift, options={**settings.options, **filled})


def descriptors_fit(descs: Descriptors, settings: DescribeSettings) -> bool:
    """Whether ``descs`` were described as ``settings`` (from ``method_settings``) asks in what a
    method decides: the panorama shift (meta "shift") and the options any method may fill in
    (meta "settings", the model's own record, which leaves out an option at its default).
    Descriptors of another descriptor than ``settings.descriptor`` are judged by the shift only."""
    from .params import METHOD_DESCRIBE_OPTIONS

    if bool(descs.meta.get("shift", True)) != bool(settings.shift):
        return False
    name = descs.meta.get("descriptor")
    if name != settings.descriptor or name not in descriptor_registry.REGISTRY:
        return True
    described = descs.meta.get("settings") or {}
    keys = {k for options in METHOD_DESCRIBE_OPTIONS.values() for k in options}
    return all(_option_value(name, k, described.get(k)) == _option_value(name, k, settings.options.get(k))
               for k in keys)


def _option_value(descriptor: str, key: str, value):
    """``value`` of option ``key``, or the descriptor's own default when None."""
    if value is not None:
        return value
    import inspect

    try:
        parameter = inspect.signature(descriptor_registry.model_class(descriptor)).parameters.get(key)
    except InputError:
        return None
    return None if parameter is None or parameter.default is inspect.Parameter.empty else parameter.default


def is_descriptor_file(path: str | Path) -> bool:
    return Path(path).suffix.lower() == ".npz"


def describe(
    path: str | Path,
    settings: DescribeSettings = DescribeSettings(),
    progress: Optional[Progress] = None,
    cancel: Optional[CancelToken] = None,
    cache: "descriptor_registry.cache.DescriptorCache | None" = None,
    model=None,
) -> Descriptors:
    """Descriptors of a recording sampled every ``settings.interval`` seconds.

    A descriptors .npz written by ``describe`` is loaded as it is. With ``cache``
    given, a previous result for the same file and settings is reused. ``model``: the
    descriptor model to use (default: a new one from ``settings``), e.g. one holding the
    vocabulary a site shares (``engine.site``).
    """
    from .descriptors.cache import cache_key
    from .features import FEATURES_VERSION
    from .verify import COLUMNS_VERSION

    path = Path(path)
    if is_descriptor_file(path):
        return Descriptors.load(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or directory")

    from .validate import interval as check_interval

    check_interval(settings.interval, "interval")
    if settings.sampling not in ("interval", "keyframes"):
        raise InputError(f"sampling: expected 'interval' or 'keyframes', got {settings.sampling!r}")
    model = model if model is not None else descriptor_registry.get(settings.descriptor, **settings.options)
    key = None
    if cache is not None:
        reading = {"interval": settings.interval, "topic": settings.topic}
        if settings.projection or settings.sampling != "interval":   # keys of earlier runs unchanged
            reading.update(projection=settings.projection, sampling=settings.sampling)
        if settings.shift and (path.is_dir() or path.suffix.lower() in (".bag", ".db3", ".mcap")):
            reading["headings"] = 1   # bags and photo folders may now be shifted by their headings
        key = cache_key(path, reading,
                        {"shift": settings.shift, "columns": COLUMNS_VERSION,
                         "features": FEATURES_VERSION, "work_width": work_width(model), **model.settings()})
        hit = cache.load(key)
        if hit is not None:
            return hit

    with open_source(path, topic=settings.topic, interval=settings.interval, projection=settings.projection,
                     keyframes_only=settings.sampling == "keyframes",
                     skip_bad_frames=settings.skip_bad_frames) as source:
        result = describe_source(source, settings, model, str(path), progress, cancel)
    if cache is not None and key is not None:
        cache.store(key, result)
    return result


def describe_source(source: FrameSource, settings: DescribeSettings, model, where: str = "",
                    progress: Optional[Progress] = None, cancel: Optional[CancelToken] = None) -> Descriptors:
    """Descriptors of an open recording: frames sampled, decoded in a thread while the previous
    ones are described (``engine.prefetch``), delivered no wider than the working copy; the
    network gets the cores the reader's decoding threads leave (``prefetch.cores_left``)."""
    from .descriptors.accel import cpu_threads
    from .frame_guard import check_describe_memory, checked_frames
    from .prefetch import cores_left, prefetched

    expected = source.expected_samples(settings.interval)
    check_describe_memory(expected, model, where)
    headings = source.headings() if settings.shift else None   # None: the shift from the image
    skipped: list[int] = []
    frames = prefetched(checked_frames(source, settings.interval, settings.skip_bad_frames, skipped,
                                       max_width=work_width(model)))
    try:
        with cpu_threads(cores_left(source.reader_threads)):
            result = describe_frames(frames, expected, settings, model=model, source=where,
                                     progress=progress, cancel=cancel, headings=headings)
    finally:
        frames.close()   # on cancel or error too: reading stops before the caller closes the source
    result.meta["skipped_frames"] = skipped
    note = getattr(source, "heading_note", "")
    result.meta["shift_from"] = ("heading" if headings is not None else "image") if settings.shift else "none"
    if note:
        result.meta["heading_note"] = note
    projection = getattr(source, "projection", None)
    result.meta["projection"] = projection.as_meta() if projection is not None else {"name": "equirect"}
    result.meta["sampling"] = settings.sampling
    notes = list(getattr(source, "notes", None) or [])
    if notes:
        result.meta["reader_notes"] = notes
    return result


def describe_frames(
    frames: Iterable[Frame],
    count: int,
    settings: DescribeSettings = DescribeSettings(),
    model=None,
    source: str = "",
    progress: Optional[Progress] = None,
    cancel: Optional[CancelToken] = None,
    headings: Optional[np.ndarray] = None,
) -> Descriptors:
    """Descriptors of already sampled ``frames`` (the core of ``describe``; also used on
    in-memory recordings by benchmarks and tests).

    The panorama shift of each frame comes from ``headings[frame.index]`` (degrees clockwise
    of the image centre, ``FrameSource.headings``) when given, else from the image
    (``engine.shift.canonical_shift``); none when ``settings.shift`` is off.

    Besides the global vectors it keeps per-column signatures of every shifted frame
    (``Descriptors.columns``), which the ``verified`` method uses for yaw-aligned checks,
    and the local features of each shifted frame (``Descriptors.features``) for two-view geometry.
    """
    from .features import FeatureTable, extract
    from .shift import apply_shift, canonical_shift, shift_from_heading
    from .verify import column_features

    if model is None:
        model = descriptor_registry.get(settings.descriptor, **settings.options)
    stamps: list[float] = []
    indices: list[int] = []
    shifts: list[int] = []
    columns: list[np.ndarray] = []
    features: list = []
    frame_width: list[int] = []

    columns_wide = work_width(model)

    def shifted_images() -> Iterator[np.ndarray]:
        for frame in frames:
            check(cancel)
            work = working_copy(frame.rgb, columns_wide)
            if not settings.shift:
                s_work = 0
            elif headings is not None:
                s_work = shift_from_heading(work.shape[1], float(headings[frame.index]))
            else:
                s_work = canonical_shift(work)
            stamps.append(frame.stamp)
            indices.append(frame.index)
            # The shift is stored in columns of the source frame (the contract).
            shifts.append(int(round(s_work * frame.width / work.shape[1])) % frame.width)
            rgb = apply_shift(work, s_work) if s_work else work
            columns.append(column_features(rgb))
            features.append(extract(rgb))
            if not frame_width:
                frame_width.append(frame.width)
            yield rgb

    vectors = model.describe(shifted_images(), count=int(count), progress=progress, cancel=cancel)
    if not stamps:
        raise InputError(f"{source or 'input'}: the recording has no frames")
    meta = {
        "descriptor": settings.descriptor,
        "settings": model.settings(),
        "defaults": dict(model.defaults),
        "interval": settings.interval,
        "topic": settings.topic,
        "shift": settings.shift,
        "source": source,
        "frame_width": int(frame_width[0]) if frame_width else 0,   # for yaw from column shifts
    }
    return Descriptors(
        stamps=np.asarray(stamps, np.float64),
        frames=np.asarray(indices, np.int64),
        shifts=np.asarray(shifts, np.int64),
        vectors=np.asarray(vectors, np.float32),
        meta=meta,
        columns=np.stack(columns).astype(np.float16) if columns else None,
        features=FeatureTable.from_list(features) if features else None,
    )


# Every per-frame step of describing works on frames at most this wide, or as wide as the
# descriptor's network input where that is wider (``work_width``): the default inputs are
# 256 (effnet-vlad), 448 (AnyLoc) and 644 columns (MegaLoc/BoQ at 322x644), local features
# use 256 columns, column signatures 512. A 3840x1920 frame cost
# 0.35-0.6 s in those steps at full size (mostly resizing and rolling 22 MB); at 2,048
# columns 88 ms, at 1,024 columns 36 ms, most of the difference in the descriptor's own
# resize and the (since retired) colour histogram (effnet-vlad 46 -> 18 ms per frame,
# timed one frame at a time on the 2-core development machine, see
# benchmarks/results/video_sampling.md). Area averaging to 1,024 and then to 256 columns
# gives the network nearly the same picture as averaging from 2,048.
WORK_WIDTH = 1024


def work_width(model) -> int:
    """Columns of the working copy for ``model``: ``WORK_WIDTH``, or its network input if wider."""
    return max(WORK_WIDTH, int(model.input_columns()))


def working_copy(rgb: np.ndarray, width: int = WORK_WIDTH) -> np.ndarray:
    """``rgb`` shrunk (area averaging, 2:1 kept) to at most ``width`` columns."""
    h, w = rgb.shape[:2]
    if w <= width:
        return rgb
    import cv2

    return cv2.resize(rgb, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)


def descriptor_defaults(descs: Descriptors, method: Optional[str] = None) -> dict:
    """The calibrated thresholds for the descriptor that made ``descs``.

    Stored defaults first, then the registered model's; descriptors of a model this
    project does not know (an .npz from any other model) get thresholds calibrated from
    the recording itself (``engine.calibrate.paper_thresholds``, sampled, fine at 100k
    rows), with the default temporal window of MapParams. ``method`` "verified" reads
    neither of those thresholds (its node threshold comes from the recording, its loops
    from calibrated scores): nothing is calibrated for it (28 s of a site of 360,000 nodes).
    """
    if descs.meta.get("defaults"):
        return dict(descs.meta["defaults"])
    name = descs.meta.get("descriptor", descriptor_registry.DEFAULT_DESCRIPTOR)
    if name in descriptor_registry.REGISTRY:
        return descriptor_registry.defaults_for(name)
    if method == "verified":
        return {}
    from .calibrate import paper_thresholds

    return paper_thresholds(descs.vectors, MapParams().neighbor_node_num)


def build_map(descs: Descriptors, params: MapParams = MapParams(), source: str = "", *,
              row_starts: Sequence[int] = (0,), sessions: Optional[Sequence[str]] = None,
              metric=None):
    """Nodes and loops from descriptors: cheap, re-run on every parameter change.

    Several recordings (``engine.site``): ``descs`` concatenated, ``row_starts`` the first row
    of each and ``sessions`` their names; nodes are made per recording, the thresholds
    calibrated on the whole set, and the pose graph treats each recording as its own chain.
    ``metric``: the recording's odometry and GPS per descriptor row (``engine.metric.Metric``;
    default: what ``engine.run`` read for these descriptors, ``descs.cache["metric"]``), which
    put the ``verified`` pose graph in metres; without it the map is image-only."""
    from .graph import TopoMap
    from .loops import detect_loops
    from .nodes import make_nodes

    from .validate import map_params

    map_params(params)
    if len(descs) == 0:
        raise InputError("no descriptors to map")
    if params.method == "verified" and params.node_sim_th is None:
        from .calibrate import node_threshold

        params = replace(params, node_sim_th=node_threshold(descs.vectors))
    p = params.resolved(descriptor_defaults(descs, params.method))
    if params.uses_shift != bool(descs.meta.get("shift", True)):
        wanted = "panorama-shifted" if params.uses_shift else "unshifted"
        raise InputError(f"method '{p.method}' needs {wanted} descriptors; describe again "
                         f"{'without' if not params.uses_shift else 'with'} --no-shift")
    bounds = [int(r) for r in row_starts] + [len(descs)]
    parts = [make_nodes(descs.vectors[s:e], p.node_sim_th) + s for s, e in zip(bounds[:-1], bounds[1:])]
    node_rows = np.concatenate(parts).astype(np.int64)
    chain_starts = np.cumsum([0] + [part.size for part in parts[:-1]]).astype(np.int64)
    node_sessions = None
    if sessions is not None:
        node_sessions = [str(name) for name, part in zip(sessions, parts) for _ in range(part.size)]
    columns = None if descs.columns is None else descs.columns[node_rows]
    frame_width = int(descs.meta.get("frame_width", 0))
    poses = None
    steps = None
    at_nodes = None
    if p.method == "verified":
        from .loops.geometry import PairGeometry
        from .loops.pose_graph import step_factors
        from .loops.verified import detect_loops as verified

        cache = descs.cache.setdefault(("nodes", p.node_sim_th), {})
        features = getattr(descs, "features", None)
        metric = metric if metric is not None else descs.cache.get("metric")
        if metric is not None and not metric.empty and metric.rows != len(descs):
            raise InputError(f"metric data for {metric.rows} frames given with {len(descs)} descriptors")
        at_nodes = None if metric is None or metric.empty else metric.take(node_rows)
        found = verified(descs.vectors[node_rows], p, node_rows=node_rows,
                         features=features, columns=columns,
                         shifts=descs.shifts[node_rows], frame_width=frame_width,
                         cache=cache, chain_starts=tuple(chain_starts.tolist()), metric=at_nodes)
        loops, poses = found.loops, found.poses
        if poses is not None:   # the step factors, for the g2o export (fits already cached)
            fitted = PairGeometry(features, node_rows, descs.shifts[node_rows], frame_width, columns, cache).steps(p)
            f = None if fitted is None else step_factors(fitted, chain_starts, p, at_nodes)
            steps = None if f is None else (f.dx, f.dy, f.dt, f.sigma_xy, f.sigma_t)
    else:
        loops = detect_loops(descs.vectors[node_rows], p)
    extra = {"descriptor": descs.meta.get("descriptor", ""), "interval": float(descs.meta.get("interval", 0.0))}
    if descs.meta.get("sampling") == "keyframes":   # the interval played no part
        extra["sampling"] = "keyframes"
    projection = (descs.meta.get("projection") or {}).get("name", "equirect")
    if projection != "equirect":                     # converted to equirectangular as read
        extra["projection"] = projection
    if poses is not None and at_nodes is not None:   # the pose graph was solved in metres, from these
        extra["metric"] = "+".join(k for k, v in (("odometry", at_nodes.odometry), ("gps", at_nodes.gps))
                                   if v is not None)
    topomap = TopoMap.build(descs, node_rows, loops, p, source=source or descs.meta.get("source", ""),
                            extra_meta=extra, sessions=node_sessions)
    if poses is not None:   # the pose graph's estimate, until ground truth or GPS replaces it
        topomap.set_positions(poses[:, 0], poses[:, 1], poses[:, 2], kind="estimated")
        topomap.step_measurements = steps
    return topomap
