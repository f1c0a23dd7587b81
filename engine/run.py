"""One run: describe, map, position and evaluate a recording.

The command line (``panotopo map``), the desktop app's worker and the benchmarks all call
``run``; each stage is one call of its own module, in this order:

1. describe   ``engine.pipeline.describe`` (a recording or a descriptors .npz) as the method
              asks (``engine.pipeline.method_settings``: panorama shift, describe options),
              skipped when ``Descriptors`` are given (the benchmarks describe frames held in memory);
2. thresholds the paper's thresholds calibrated from the recording, for those not set
              (``auto_thresholds``; ``engine.calibrate.paper_thresholds``);
3. map        ``engine.pipeline.build_map``: nodes and loops;
   (metric)   with ``metric``, the recording's own odometry (a bag's Odometry / PoseStamped
              topic) and GPS (EXIF, GPMF) at the descriptor stamps (``engine.metric``): the
              pose graph of ``verified`` is then solved in metres; none of it is ground truth;
4. position   node positions from ground-truth ``poses`` (given, or the recording's own:
              a geotagged photo folder's EXIF GPS) where known, else the pose graph's
              estimate (graph ``positions`` "estimated", never read as ground truth);
5. evaluate   ``engine.evaluate.evaluate`` against those poses, where known and asked.

Several recordings (a list or tuple ``source``: recordings, .npz, site maps) are one site:
stages 1-3 are ``engine.site.map_site`` (each recording described or loaded, one map);
``poses`` is then a dict session -> Poses (evaluation only: the nodes keep the pose graph's
estimate), and a site that falls apart adds one warning (``engine.site.components_line``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Optional, Union

from .descriptors.base import Descriptors
from .params import MapParams
from .poses import Poses


@dataclass
class RunResult:
    descs: Descriptors
    topomap: object                        # engine.graph.TopoMap
    poses: Optional[Poses] = None          # what positioned the nodes, when known
    evaluation: Optional[object] = None    # engine.evaluate.Evaluation, when poses and asked
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)      # what was used (e.g. which odometry topic), one line each
    metric: Optional[object] = None        # engine.metric.Metric the pose graph used, per descriptor row


def run(source: Union[str, Path, Descriptors], params: MapParams = MapParams(), *, settings=None,
        poses: Optional[Poses] = None, recording_poses: bool = False, auto_thresholds: bool = False,
        evaluate: bool = False, eval_nn: Optional[int] = None, progress=None, cancel=None,
        cache=None, poses_name: str = "poses", metric: bool = False,
        odom_topic: Optional[str] = None) -> RunResult:
    """Stages 1-5 (module notes). ``settings`` is an ``engine.pipeline.DescribeSettings``, the
    user's: its ``shift`` and the describe options the method asks for follow the method
    (``engine.pipeline.method_settings``); ``recording_poses`` looks for positions in the
    recording itself when ``poses`` is None; ``eval_nn`` overrides the map's temporal
    window for evaluation; ``poses_name`` names the poses in an error. ``metric``: the
    recording's own odometry and GPS become factors of the pose graph (``odom_topic``: the
    bag's odometry topic; None: its one Odometry / PoseStamped topic; "none": no odometry)."""
    from .pipeline import build_map, describe, is_descriptor_file, method_settings
    from .progress import check

    if isinstance(source, (list, tuple)):
        return _run_site(list(source), params, settings=settings, poses=poses, auto_thresholds=auto_thresholds,
                         evaluate=evaluate, eval_nn=eval_nn, progress=progress, cancel=cancel, cache=cache)
    warnings: list[str] = []
    positions = "ground truth"   # graph attribute: what positioned the nodes
    odometry = None
    named = odom_topic not in (None, "none")
    if named and (not metric or params.method != "verified" or isinstance(source, Descriptors)):
        from .errors import InputError

        raise InputError(f"an odometry topic ({odom_topic}) is read from a bag for the verified method's pose graph")
    metric = metric and params.method == "verified"   # only its pose graph reads metric data
    if isinstance(source, Descriptors):                                            # 1
        descs, name = source, str(source.meta.get("source", ""))
    else:
        settings = method_settings(params, settings)
        if metric:   # read (and checked against the frames) before the long part, describing
            from .metric import bag_odometry

            odometry = bag_odometry(Path(source), odom_topic, image_topic=settings.topic,
                                    interval=settings.interval)
        descs = describe(source, settings, progress=progress, cancel=cancel, cache=cache)
        name = "" if is_descriptor_file(source) else str(source)
    if auto_thresholds:                                                            # 2
        from .calibrate import paper_thresholds

        found = paper_thresholds(descs.vectors, params.neighbor_node_num)
        params = replace(params, **{k: v for k, v in found.items() if getattr(params, k) is None})
    check(cancel)
    recorded = None
    if not isinstance(source, Descriptors) and ((poses is None and recording_poses) or metric):
        from .sources import recording_poses as own_poses

        recorded, own_warnings = own_poses(Path(source), interval=settings.interval)
        warnings.extend(own_warnings)
    notes: list[str] = []
    used = None
    descs.cache.pop("metric", None)   # build_map's default: what was read here for these descriptors
    if metric and not isinstance(source, Descriptors):                             # (metric)
        from .metric import read_metric

        used = read_metric(Path(source), descs.stamps, gps=recorded, odometry=odometry)
        notes.extend(used.notes)
        warnings.extend(used.warnings)
        used = None if used.empty else used
        if used is not None:
            descs.cache["metric"] = used
    if progress is not None:
        progress(0, 0, "building the map")
    topomap = build_map(descs, params, source=name, metric=used)                  # 3
    check(cancel)
    if poses is None and recording_poses and not isinstance(source, Descriptors):   # 4
        poses = recorded
        if poses is not None:   # EXIF or GPMF fixes: a track that misses the nodes is a warning
            from .errors import InputError
            from .validate import poses_cover

            positions = "gps"
            try:
                poses_cover(poses, topomap.stamps(), "the recording's own GPS")
            except InputError as err:
                warnings.append(f"no node positions: {err}")
                poses = None
    if poses is not None:
        from .validate import poses_cover

        poses_cover(poses, topomap.stamps(), poses_name)
        x, y = poses.at(topomap.stamps())
        topomap.set_positions(x, y)
        topomap.graph.graph["positions"] = topomap.meta["positions"] = positions
    evaluation = None
    if evaluate and poses is not None:                                             # 5
        from .evaluate import evaluate as score

        evaluation = score(topomap, poses, neighbor_node_num=eval_nn)
    return RunResult(descs, topomap, poses, evaluation, warnings, notes, used)


def _run_site(sources: list, params: MapParams, *, settings, poses, auto_thresholds: bool, evaluate: bool,
              eval_nn, progress, cancel, cache) -> RunResult:
    """``run`` of several recordings (module notes)."""
    from .site import components_line, map_site

    out = map_site(sources, params, settings, cache=cache, auto_thresholds=auto_thresholds,
                   progress=progress, cancel=cancel)
    warnings = list(out.notes)
    line = components_line(out.components)
    if line:
        warnings.append(line)
    evaluation = None
    if evaluate and poses is not None:
        from .evaluate import evaluate as score

        evaluation = score(out.topomap, poses, neighbor_node_num=eval_nn)
    return RunResult(out.descs, out.topomap, poses, evaluation, warnings)
