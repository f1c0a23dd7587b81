"""The ``panotopo`` command: map, describe, eval, demo (the desktop app adds gui).

Bad input ends with one line on stderr and a non-zero exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Callable, Optional, Sequence

from . import __version__
from .errors import Cancelled, PanotopoError
from .params import METHODS, PARAMETERS, MapParams

EXIT_BAD_INPUT = 2
EXIT_CANCELLED = 130


# ----------------------------------------------------------------------------- helpers

class _Parser(argparse.ArgumentParser):
    """argparse with its errors in the one-line form of every other error (no usage block)."""

    def error(self, message: str):
        print(f"panotopo: error: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


class _Bar:
    """A tqdm progress bar on stderr fed by the engine's (done, total, stage) callback.

    The unit is the stage's (``engine.loops.paper.PROGRESS_UNITS``: tiles or nodes of the
    loop search), frames otherwise; a stage of unknown size (total 0) shows only its name
    and the time spent, never a count of "0frame"; a bar is drawn when it starts and
    redrawn only when its count changes (a new bar is not drawn twice)."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.bar = None
        self.stage = None

    def __call__(self, done: int, total: int, stage: str) -> None:
        if self.quiet:
            return
        from tqdm import tqdm

        from .loops.paper import PROGRESS_UNITS

        if self.bar is None or stage != self.stage or (total and self.bar.total is None):
            self.close()
            plain = {} if total else {"bar_format": "{desc} [{elapsed}]"}
            self.bar = tqdm(total=total or None, desc=stage, unit=PROGRESS_UNITS.get(stage, "frame"),
                            initial=done, file=sys.stderr, leave=False, **plain)
            self.stage = stage
            return
        if total and self.bar.total != total:
            self.bar.total = total
        if done != self.bar.n:
            self.bar.n = done
            self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _descriptor_options(args: argparse.Namespace) -> dict:
    """Descriptor-specific options given on the command line (only those set)."""
    names = ("weights", "vocabulary", "backbone", "layer", "facet", "device", "batch_size", "input_height", "pca_dim",
             "precision", "phases", "photometric")
    opts = {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}
    if getattr(args, "allow_download", False):
        opts["allow_download"] = True
    return opts


def _cache(args: argparse.Namespace):
    if getattr(args, "no_cache", False):
        return None
    from .descriptors.cache import DescriptorCache

    return DescriptorCache(Path(args.cache_dir) if getattr(args, "cache_dir", None) else None)


def _describe_settings(args: argparse.Namespace, shift: bool):
    """The user's describe settings (``run`` adds what the map's method asks for)."""
    from .pipeline import DescribeSettings

    from .validate import describe_options

    options = describe_options(args.descriptor, _descriptor_options(args), name=_argument_name)
    keyframes = args.interval == KEYFRAMES
    return DescribeSettings(
        descriptor=args.descriptor, interval=1.0 if keyframes else args.interval, topic=args.topic,
        shift=shift, options=options, skip_bad_frames=args.skip_bad_frames,
        projection=getattr(args, "projection", None), sampling="keyframes" if keyframes else "interval",
    )


def _report_skipped(args: argparse.Namespace, descs) -> None:
    for note in getattr(descs, "notes", ()):   # what loading a descriptors file mended (rows normalised)
        print(f"panotopo: {note}", file=sys.stderr)
    for note in descs.meta.get("reader_notes") or []:   # e.g. a video cut short, read as far as it goes
        print(f"panotopo: {note}", file=sys.stderr)
    skipped = descs.meta.get("skipped_frames") or []
    if skipped:
        print(f"panotopo: skipped {len(skipped)} undecodable frame(s) of {args.input} "
              f"(first: {skipped[0]})", file=sys.stderr)


def _describe_command_settings(args: argparse.Namespace):
    """The settings of ``describe``: as ``--method`` asks (as ``map`` would describe), unshifted
    under ``--no-shift`` (the single form and the batch form alike)."""
    from dataclasses import replace

    from .pipeline import method_settings

    settings = method_settings(MapParams(method=args.method), _describe_settings(args, True))
    if args.no_shift:
        settings = replace(settings, shift=False)
    return settings


def _describe(args: argparse.Namespace):
    """``describe`` of the one INPUT with ``_describe_command_settings``."""
    from .pipeline import describe

    settings = _describe_command_settings(args)
    bar = _Bar(args.quiet)
    try:
        descs = describe(args.input, settings, progress=bar, cache=_cache(args))
    finally:
        bar.close()
    _report_skipped(args, descs)
    return descs


def _map_params(args: argparse.Namespace) -> MapParams:
    return MapParams(**{p.name: getattr(args, p.name) for p in PARAMETERS if hasattr(args, p.name)})


def _add_table_parameters(p: argparse.ArgumentParser) -> None:
    """Options of the ``verified`` method, built from ``engine.params.PARAMETERS``."""
    g = p.add_argument_group("verified method (defaults and their origin: engine/params.py)")
    for par in PARAMETERS:
        if par.methods == ("verified",):
            g.add_argument("--" + par.name.replace("_", "-"), type=par.type, default=par.default,
                           help=f"{par.help} (default: {par.default})")


def _argument_name(key: str) -> str:
    return "--" + key.replace("_", "-")


def _check_arguments(args: argparse.Namespace) -> None:
    """Every numeric argument and every output, before anything slow runs (limits:
    engine/limits.py): one clear line instead of a traceback or a silent nonsense result."""
    from . import limits, validate
    from .outputs import check_output

    if args.command == "describe":
        from .batch import check_form

        check_form(args)   # -o OUT.npz (one INPUT) or --out-dir DIR (a batch); sets args.input
    if getattr(args, "interval", None) not in (None, KEYFRAMES):
        validate.interval(args.interval)
    if getattr(args, "method", None) is not None:
        validate.map_params(_map_params(args), name=_argument_name)
    if getattr(args, "dist_th", None) is not None:
        validate.number(args.dist_th, "--dist-th", above=0.0, hi=limits.MAX_DIST_TH_M)
    if getattr(args, "found_within", None) is not None:
        validate.number(args.found_within, "--found-within", above=0.0, hi=limits.MAX_DIST_TH_M)
        validate.number(args.false_beyond, "--false-beyond", lo=args.found_within, hi=limits.MAX_DIST_TH_M)
    if args.command == "demo":
        validate.integer(args.seed, "--seed", lo=0, hi=limits.MAX_SEED)
        validate.integer(args.width, "--width", lo=limits.MIN_DEMO_WIDTH, hi=limits.MAX_DEMO_WIDTH)
        if args.input_height is not None:
            validate.integer(args.input_height, "--input-height", lo=limits.MIN_INPUT_HEIGHT,
                             hi=limits.MAX_INPUT_HEIGHT)
    inputs = []
    for k in ("input", "map", "poses"):
        value = getattr(args, k, None)
        inputs += list(value) if isinstance(value, (list, tuple)) else [value]
    inputs = [_poses_path(v) if isinstance(v, str) else v for v in inputs]
    if isinstance(getattr(args, "g2o", None), str):
        check_output(args.g2o, inputs + [args.output, getattr(args, "plot", None), getattr(args, "json", None)])
    for key in ("output", "plot", "json"):
        if getattr(args, key, None) and isinstance(getattr(args, key), str):
            check_output(getattr(args, key), inputs)
    if getattr(args, "output", None) and getattr(args, "plot", None):
        check_output(args.plot, [args.output])
    if getattr(args, "json", None) and isinstance(args.json, str):
        check_output(args.json, [args.output, getattr(args, "plot", None)])
    _distinct_paths(args)


def _same_path(a: str, b: str) -> bool:
    """Whether two paths name one file: the same file on disk (a hard link, a symlink), or,
    for a file that does not exist yet, the same absolute path once symlinks are resolved."""
    import os

    try:
        if os.path.samefile(a, b):
            return True
    except OSError:  # one does not exist (yet)
        pass
    return os.path.realpath(os.path.expanduser(a)) == os.path.realpath(os.path.expanduser(b))


def _distinct_paths(args: argparse.Namespace) -> None:
    """Refuse a command whose outputs name one file twice, or name one of its inputs, also
    when none exists yet (``-o m.graphml --plot m.graphml`` wrote the map, then the picture
    over it, and exited 0)."""
    from .errors import InputError

    named = [(f"--{k}", getattr(args, k, None)) for k in ("output", "plot", "json", "g2o")]
    named = [(flag, path) for flag, path in named if isinstance(path, str) and path]
    inputs = []
    for key in ("input", "map", "poses"):
        value = getattr(args, key, None)
        inputs += [v for v in (value if isinstance(value, (list, tuple)) else [value]) if isinstance(v, str) and v]
    for i, (flag, path) in enumerate(named):
        for other_flag, other in named[:i]:
            if _same_path(path, other):
                raise InputError(f"{flag} {path}: the same file as {other_flag} {other}; "
                                 f"each output needs its own name")
        for src in inputs:
            if _same_path(path, src):
                raise InputError(f"{flag} {path}: the same file as the input {src}; choose another output name")


def _poses_path(text: str) -> str:
    """The file of a ``--poses`` value (``SESSION=PATH`` names a recording of a site)."""
    name, sep, rest = text.partition("=")
    return rest if sep and name and not Path(text).exists() else text


def _load_poses(path: str, topic: Optional[str]):
    from .sources import read_poses

    return read_poses(Path(path), topic=topic)


def _say(args: argparse.Namespace, text: str) -> None:
    if not args.quiet:
        print(text)


# ----------------------------------------------------------------------------- commands

def cmd_describe(args: argparse.Namespace) -> int:
    if args.out_dir is not None:   # a batch on Dask (engine/batch.py, docs/cluster.md)
        from .batch import run_command

        return run_command(args, _describe_command_settings(args), say=lambda text: _say(args, text),
                           warn=lambda text: print(f"panotopo: {text}", file=sys.stderr))
    descs = _describe(args)
    descs.save(args.output)
    _say(args, f"wrote {args.output}: {len(descs)} descriptors of dimension {descs.vectors.shape[1]}")
    return 0


def _map_site(args: argparse.Namespace, inputs: list) -> int:
    """``map A B C`` (or ``map SITE.graphml D``): one map of several recordings (engine/site.py)."""
    from .errors import InputError
    from .exports import write_map
    from .loops.paper import loop_progress
    from .site import components_line, map_site

    if args.poses:
        raise InputError("--poses positions a map of one recording; for several, give each recording's "
                         "poses to 'panotopo eval SITE.graphml --poses NAME=PATH ...'")
    if args.odom_topic is not None:
        raise InputError("--odom-topic is read for a map of one recording; a map of several is image-only")
    params = _map_params(args)
    bar = _Bar(args.quiet)
    try:
        with loop_progress(bar):
            out = map_site(inputs, params, _describe_settings(args, params.uses_shift), cache=_cache(args),
                           auto_thresholds=args.auto_thresholds, progress=bar)
    finally:
        bar.close()
    for line in out.notes:
        print(f"panotopo: {line}", file=sys.stderr)
    topomap = out.topomap
    write_map(topomap, args.output, keep_candidates=args.keep_candidates)
    cross = sum(1 for u, v, _ in topomap.loops(("auto", "confirmed", "manual"))
                if topomap.graph.nodes[u]["session"] != topomap.graph.nodes[v]["session"])
    _say(args, f"wrote {args.output}: {len(out.sessions)} recordings, {topomap.node_count} nodes, "
               f"{len(topomap.loops())} loops ({cross} across recordings; method {topomap.meta.get('method')}, "
               f"descriptor {topomap.meta.get('descriptor')})")
    line = components_line(out.components)
    if line:
        print(f"warning: {line}", file=sys.stderr)
    _write_extras(args, topomap)
    return 0


def cmd_map(args: argparse.Namespace) -> int:
    from .run import run
    from .site import is_site_map

    inputs = list(args.input) if isinstance(args.input, (list, tuple)) else [args.input]
    if len(inputs) > 1 or is_site_map(inputs[0]):
        return _map_site(args, inputs)
    args.input = inputs[0]
    params = _map_params(args)
    poses = _load_poses(args.poses, args.pose_topic) if args.poses else None
    from .loops.paper import loop_progress

    bar = _Bar(args.quiet)
    try:
        with loop_progress(bar):  # the loop search's progress (engine.run does not pass it down)
            out = run(args.input, params, settings=_describe_settings(args, params.uses_shift), poses=poses,
                      recording_poses=poses is None, auto_thresholds=args.auto_thresholds,
                      evaluate=bool(args.plot), progress=bar, cache=_cache(args), poses_name=str(args.poses),
                      metric=True, odom_topic=args.odom_topic)
    finally:
        bar.close()
    _report_skipped(args, out.descs)
    for line in out.notes:
        _say(args, line)
    for line in out.warnings + _circular(args, out):
        print(f"warning: {line}", file=sys.stderr)
    topomap = out.topomap
    from .exports import write_map

    bar = _Bar(args.quiet)
    try:  # a map of many loops takes minutes to write (GraphML of 740,000 loops: about 2 min)
        bar(0, 0, f"writing {args.output}")
        write_map(topomap, args.output, keep_candidates=args.keep_candidates)   # .json: node-link JSON
    finally:
        bar.close()
    loops = topomap.loops()
    _say(args, f"wrote {args.output}: {topomap.node_count} nodes, {len(loops)} loops "
               f"(method {topomap.meta.get('method')}, descriptor {topomap.meta.get('descriptor')})")
    _write_extras(args, topomap, out.poses, out.evaluation)
    return 0


def _circular(args: argparse.Namespace, out) -> list[str]:
    """One line when the poses given to evaluate against are the odometry the map was built
    with (the same bag and topic): such an evaluation is not independent."""
    topic = getattr(out.metric, "odometry_topic", "") if out.metric is not None else ""
    if not (topic and args.poses and _same_path(args.poses, args.input)):
        return []
    if args.pose_topic not in (None, topic):
        return []
    return [f"the poses ({args.poses} {topic}) are the odometry the pose graph was built with: an evaluation "
            f"against them is not independent (map with --odom-topic none to keep them apart)"]


def _write_extras(args: argparse.Namespace, topomap, poses=None, evaluation=None) -> None:
    """The outputs asked for beside the map: node-link JSON, g2o, a picture."""
    from .exports import write_g2o, write_node_link_json

    if getattr(args, "json", None):
        write_node_link_json(topomap, args.json, keep_candidates=args.keep_candidates)
        _say(args, f"wrote {args.json} (networkx node-link JSON)")
    if getattr(args, "g2o", None):
        write_g2o(topomap, args.g2o, keep_candidates=args.keep_candidates)
        _say(args, f"wrote {args.g2o} (g2o pose graph)")
    if args.plot:
        from .plots import plot_map
        plot_map(topomap, poses, evaluation, args.plot)
        _say(args, f"wrote {args.plot}")


def _evaluation_dict(ev) -> dict:
    keys = ("tp", "fp", "tn", "fn", "precision", "recall", "accuracy", "f1")
    out = {k: getattr(ev, k) for k in keys}
    for extra in ("events_found", "events_total"):
        if hasattr(ev, extra):
            out[extra] = getattr(ev, extra)
    if getattr(ev, "sessions", 1) > 1:   # a site: within and across recordings apart
        c = {k: getattr(ev, f"cross_{k}") for k in ("tp", "fp", "fn", "events_found", "events_total")}
        out["recordings"] = ev.sessions
        out["across"] = c
        out["within"] = {"tp": ev.tp - c["tp"], "fp": ev.fp - c["fp"], "fn": ev.fn - c["fn"],
                         "events_found": ev.events_found - c["events_found"],
                         "events_total": ev.events_total - c["events_total"]}
    out["undefined"] = list(ev.undefined())  # ratios with a zero denominator: their 0.0 means n/a
    return out


def _evaluation_lines(ev) -> str:
    d = _evaluation_dict(ev)
    lines = [f"TP {d['tp']}  FP {d['fp']}  TN {d['tn']}  FN {d['fn']}",
             f"precision {ev.ratio_text('precision')}  recall {ev.ratio_text('recall')}  "
             f"accuracy {ev.ratio_text('accuracy')}  F1 {ev.ratio_text('f1')}"]
    if "events_total" in d:
        lines.append(f"revisit events found {d['events_found']}/{d['events_total']}")
    if "across" in d:
        for part in ("within", "across"):
            c = d[part]
            lines.append(f"{part} recordings: TP {c['tp']}  FP {c['fp']}  FN {c['fn']}  "
                         f"places found {c['events_found']}/{c['events_total']}")
    return "\n".join(lines)


def cmd_eval(args: argparse.Namespace) -> int:
    from .evaluate import evaluate, evaluate_band
    from .graph import TopoMap

    topomap = TopoMap.read_graphml(args.map)
    given = list(args.poses)
    sessions = topomap.node_sessions()
    if sessions is None and len(given) == 1:
        poses = _load_poses(_poses_path(given[0]), args.pose_topic)
    else:
        poses = _site_poses(topomap, given, args.pose_topic)
    ev = evaluate(topomap, poses, dist_th=args.dist_th)
    # The project's figures beside the paper's table (which stays at --dist-th): the band.
    band = evaluate_band(topomap, poses, found_within=args.found_within, false_beyond=args.false_beyond)
    if args.json:
        print(json.dumps({**_evaluation_dict(ev), "band": {k: v for k, v in band.as_dict().items()
                                                           if k != "loop_band"}}))
    else:
        print(_evaluation_lines(ev) + "\nproject: " + band.text())
    if args.plot:
        from .plots import plot_map
        plot_map(topomap, poses, ev, args.plot)
    return 0


def _site_poses(topomap, given: list, topic: Optional[str]) -> dict:
    """Each recording's poses: ``NAME=PATH`` by session name, plain paths in the order of the
    map's recordings (those not named)."""
    from .errors import InputError

    names = list(dict.fromkeys((topomap.node_sessions() if topomap.node_sessions() is not None
                                else ["" for _ in range(1)]).tolist()))
    out: dict = {}
    plain = []
    for text in given:
        name, sep, path = text.partition("=")
        if sep and name in names and not Path(text).exists():
            if name in out:
                raise InputError(f"--poses {text}: poses of {name} given twice")
            out[name] = _load_poses(path, topic)
        else:
            plain.append(text)
    rest = [n for n in names if n not in out]
    if len(plain) != len(rest):
        raise InputError(f"the map has {len(names)} recordings ({', '.join(names)}); "
                         f"give one --poses per recording (in that order, or as NAME=PATH), got {len(given)}")
    for name, text in zip(rest, plain):
        out[name] = _load_poses(text, topic)
    return out


def cmd_demo(args: argparse.Namespace) -> int:
    from .pipeline import DescribeSettings
    from .plots import plot_map
    from .run import run
    from .synth import make_recording

    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    _say(args, f"writing the demo into {out}")
    _say(args, "rendering the demo route (synthetic 360-degree recording)...")
    rec = make_recording(route="demo", look=args.look, seed=args.seed, width=args.width, height=args.width // 2)
    written = _write_demo_recording(rec, out)
    for kind, path in written.items():
        _say(args, f"  {kind:14s} {path}")
    bar = _Bar(args.quiet)
    try:
        options = {"input_height": args.input_height} if args.input_height else {}
        result = run(written["video"], MapParams(), settings=DescribeSettings(interval=args.interval, options=options),
                     poses=rec.poses, evaluate=True, progress=bar)
    finally:
        bar.close()
    topomap, ev = result.topomap, result.evaluation
    graphml = out / "demo.graphml"
    topomap.write_graphml(graphml)
    plot = out / "demo_map.png"
    plot_map(topomap, rec.poses, ev, plot)
    _say(args, f"map: {topomap.node_count} nodes, {len(topomap.loops())} loops (method {topomap.meta.get('method')})")
    _say(args, _evaluation_lines(ev))
    _say(args, f"wrote {graphml}\nwrote {plot}")
    return 0


DEMO_JPEG_QUALITY = 90  # visually lossless on the synthetic panoramas, ~10x smaller than raw


def _write_demo_recording(rec, out: Path) -> dict:
    """The demo recording as a video, poses and three bags of JPEG-compressed images.

    Raw-image bags of the demo route weigh about 200 MB each (506 frames of 512x256 RGB);
    as CompressedImage (JPEG, quality 90, what camera drivers publish) the three together
    stay around 20 MB and open the same way. No PNG folder: the video shows the same frames.
    """
    from .synth import write_recording
    from .synth import writers

    written = write_recording(rec, out, formats=("video", "poses"))
    frames, stamps = list(rec.frames), [float(s) for s in rec.stamps]
    jpeg = dict(compressed=True, image_format="jpeg", jpeg_quality=DEMO_JPEG_QUALITY, poses=rec.poses,
                topic="/camera/image_raw/compressed")
    written["ros1"] = writers.write_ros1_bag(out / f"{rec.route}.bag", frames, stamps, **jpeg)
    for storage in ("sqlite3", "mcap"):
        written[f"ros2-{storage}"] = writers.write_ros2_bag(out / f"{rec.route}_ros2_{storage}", frames, stamps,
                                                            storage=storage, **jpeg)
    return written


# ----------------------------------------------------------------------------- parser

KEYFRAMES = "keyframes"


def _interval_argument(text: str):
    """``--interval``: seconds (float), or ``keyframes``."""
    if str(text).strip().lower() == KEYFRAMES:
        return KEYFRAMES
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds or 'keyframes', got {text!r}") from None


def _add_sampling(p: argparse.ArgumentParser) -> None:
    from .descriptors import DEFAULT_DESCRIPTOR
    from .descriptors.efficientnet import PHOTOMETRIC

    p.add_argument("--descriptor", default=DEFAULT_DESCRIPTOR, help="descriptor name (default: %(default)s)")
    p.add_argument("--interval", type=_interval_argument, default=1.0, metavar="SECONDS|keyframes",
                   help="sampling interval in seconds (default: 1.0), or 'keyframes': a video's key frames "
                        "only (fastest; stamps as far from regular as the key frames are)")
    p.add_argument("--topic", help="image topic of a ROS bag (needed when it has several)")
    p.add_argument("--projection", metavar="NAME[:fov=D,roll=A/B]",
                   help="what the frames are when the file cannot say: equirect, dual-fisheye (two fisheyes "
                        "side by side, or one per video stream; fov = lens field of view in degrees, roll = "
                        "turn of each lens image) or eac (equi-angular cubemap); default: read from the "
                        "file (.insv, GoPro .360), else equirect")
    g = p.add_argument_group("descriptor options")
    g.add_argument("--weights", help="checkpoint file (AnyLoc: dinov2_vit*14*_pretrain.pth; megaloc: model.safetensors "
                   "or megaloc.torch; boq: dinov2_12288.pth)")
    g.add_argument("--allow-download", action="store_true", help="let torch hub download missing weights")
    g.add_argument("--vocabulary", help="VLAD vocabulary: 'map' (build from the recording), a c_centers.pt file or a domain name")
    g.add_argument("--backbone", help="AnyLoc backbone: vits14, vitb14, vitl14, vitg14 (+ _reg); default: read from --weights")
    g.add_argument("--layer", type=int, help="AnyLoc feature layer")
    g.add_argument("--facet", choices=("value", "key", "query", "token"), help="AnyLoc facet")
    g.add_argument("--device", help="auto, cpu, cuda or mps")
    g.add_argument("--precision", choices=("auto", "float32", "bfloat16", "float16"),
                   help="network arithmetic: auto = bfloat16 + TF32 on CUDA, float32 elsewhere (docs/gpu.md)")
    g.add_argument("--batch-size", type=int)
    g.add_argument("--input-height", type=int, help="descriptor input height in pixels (width = 2 x height)")
    g.add_argument("--pca-dim", type=int, help="project descriptors to this dimension (AnyLoc)")
    g.add_argument("--phases", type=int, help="effnet-vlad: pool the features of this many rolls of the panorama "
                   "within one feature stride (1, 2, 4, 8, 16; default 1): steadier under heading changes, "
                   "that many times the network's cost")
    g.add_argument("--photometric", choices=PHOTOMETRIC,
                   help="effnet-vlad: 'standardise' gives the network each frame with its colour channels at zero "
                   "mean and unit spread, so that exposure and white balance changes between visits count less "
                   "(default: what the method asks for, engine/params.py METHOD_DESCRIBE_OPTIONS: standardise "
                   "for verified, none for the others)")
    p.add_argument("--skip-bad-frames", action="store_true",
                   help="skip frames that cannot be decoded (and say how many) instead of stopping")
    p.add_argument("--no-cache", action="store_true", help="do not read or write the descriptor cache")
    p.add_argument("--cache-dir", help="descriptor cache folder (default: $PANOTOPO_CACHE or ~/.cache/panotopo)")


# (subparsers, common parent parser) -> None: adds one command.
AddCommand = Callable[[argparse._SubParsersAction, argparse.ArgumentParser], None]


def build_parser(extra_commands: Sequence[AddCommand] = ()) -> argparse.ArgumentParser:
    parser = _Parser(
        prog="panotopo", description="Topological maps from 360-degree recordings (panorama shift + place recognition).")
    parser.add_argument("--version", action="version", version=f"panotopo {__version__}")
    # -q works before or after the command name.
    common = _Parser(add_help=False)
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="print only errors")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("map", parents=[common], help="build a topological map (GraphML) from a recording")
    p.add_argument("input", nargs="+", metavar="INPUT",
                   help="video, ROS1 .bag, ROS2 bag (directory, .db3, .mcap), image folder, or descriptors .npz; "
                        "several make one map of a site (each a 'session'), and a site .graphml among them "
                        "adds the others to it (its recordings and decisions kept)")
    p.add_argument("-o", "--output", required=True,
                   help="output map: .graphml, .json for networkx node-link JSON, or .g2o for the pose graph "
                        "(engine/exports.py)")
    p.add_argument("--json", metavar="PATH", help="also write the map as networkx node-link JSON")
    p.add_argument("--g2o", metavar="PATH", help="also write the pose graph as g2o (VERTEX_SE2 / EDGE_SE2)")
    p.add_argument("--method", default=MapParams().method, choices=METHODS,
                   help="loop detection method (default: %(default)s; 'ours' is the paper's)")
    _add_sampling(p)
    p.add_argument("--node-sim-th", type=float, help="node similarity threshold (default: the descriptor's)")
    p.add_argument("--loop-sim-th", type=float, help="loop similarity threshold (default: the descriptor's)")
    p.add_argument("--window-size", type=int, default=5)
    p.add_argument("--count-th", type=int, default=2)
    p.add_argument("--neighbor-node-num", type=int, default=MapParams().neighbor_node_num)
    p.add_argument("--auto-thresholds", action="store_true",
                   help="simple / shift-simple / ours: calibrate the node and loop thresholds not given "
                        "from the recording itself (as the benchmark does) instead of the descriptor's")
    _add_table_parameters(p)
    p.add_argument("--keep-candidates", action="store_true",
                   help="verified: also write the loop candidates waiting for review (status 'candidate')")
    p.add_argument("--poses", help="ground-truth poses (CSV t,x,y[,yaw] or a bag) to store node positions "
                                    "(default for a photo folder: its EXIF GPS, when every photo has a fix)")
    p.add_argument("--pose-topic", help="pose topic in a bag (Odometry or PoseStamped)")
    p.add_argument("--odom-topic", metavar="TOPIC|none",
                   help="verified: the bag's odometry (Odometry or PoseStamped) that puts the pose graph in "
                        "metres (default: its one such topic, if it has exactly one; 'none': image-only); "
                        "a photo folder's or GoPro video's own GPS is used the same way")
    p.add_argument("--plot", help="also write a PNG of the map")
    p.set_defaults(func=cmd_map)

    p = sub.add_parser("describe", parents=[common], help="compute descriptors and save them as .npz")
    p.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="a recording (with -o), or several described as one batch (with --out-dir)")
    p.add_argument("-o", "--output", help="output .npz (one INPUT)")
    p.add_argument("--out-dir", help="describe every INPUT as one batch on Dask into DIR/<input file name>.npz; "
                   "finished files are kept, a rerun describes only what is missing (docs/cluster.md)")
    p.add_argument("--scheduler", help="with --out-dir: address of a running Dask scheduler "
                   "(tcp://host:8786; default: a local cluster)")
    p.add_argument("--workers", type=int, help="with --out-dir: workers of the local cluster "
                   "(default: one per GPU, else one per CPU core)")
    p.add_argument("--method", default=MapParams().method, choices=METHODS,
                   help="describe as this loop detection method asks (its panorama shift and describe "
                        "options; default: %(default)s), so that 'map' of the .npz with that method "
                        "equals 'map' of the recording")
    p.add_argument("--no-shift", action="store_true", help="do not apply the panorama shift (whatever --method asks)")
    _add_sampling(p)
    p.set_defaults(func=cmd_describe)

    p = sub.add_parser("eval", parents=[common], help="evaluate a map against ground-truth poses (the paper's metrics)")
    p.add_argument("map", help="a .graphml written by panotopo")
    p.add_argument("--poses", required=True, action="append",
                   help="CSV t,x,y[,yaw] on the map's clock, or a bag; a map of several recordings takes one "
                        "--poses per recording (all in one world frame), in the map's order or as NAME=PATH")
    p.add_argument("--pose-topic", help="pose topic in a bag")
    p.add_argument("--dist-th", type=float, default=1.0, help="same-place distance in metres (default: 1.0)")
    p.add_argument("--found-within", type=float, default=1.0, metavar="M",
                   help="the project's figures: a place is found by a loop whose two views are within M metres "
                        "(default: %(default)s)")
    p.add_argument("--false-beyond", type=float, default=2.0, metavar="M",
                   help="the project's figures: a loop more than M metres apart is false; loops between "
                        "--found-within and M are neither right nor false (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")
    p.add_argument("--plot", help="also write a PNG of the evaluated map")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("demo", parents=[common], help="generate a synthetic recording, map it and evaluate it (offline)")
    p.add_argument("--out", default="panotopo-demo",
                   help="output folder, created if needed (default: ./%(default)s; about 47 MB: a video, three bags, poses, the map)")
    p.add_argument("--look", default="indoor", choices=("indoor", "outdoor"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--interval", type=float, default=1.0)
    p.add_argument("--width", type=int, default=512, help="panorama width in pixels (height = width / 2)")
    p.add_argument("--input-height", type=int, help="descriptor input height (default: the descriptor's)")
    p.set_defaults(func=cmd_demo)

    for add_command in extra_commands:
        add_command(sub, common)
    return parser


def main(argv: Optional[Sequence[str]] = None, extra_commands: Sequence[AddCommand] = ()) -> int:
    """Run the command line; ``extra_commands`` lets a higher layer (the desktop app's
    ``gui`` command) plug in without the engine ever importing it."""
    import os
    import warnings

    # The user gets panotopo's one-line answers, not library chatter: OpenCV's decoder
    # warnings (a corrupt image) and numpy's RuntimeWarnings (bad values are refused by
    # the checks; what is left is harmless arithmetic such as 0/0 in an empty statistic).
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    warnings.simplefilter("ignore", RuntimeWarning)
    parser = build_parser(extra_commands)
    args = parser.parse_args(argv)
    try:
        _check_arguments(args)
        return int(args.func(args) or 0)
    except MemoryError:
        print("panotopo: error: not enough memory for this input (see the limits in README.md)", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Cancelled:
        print("panotopo: cancelled", file=sys.stderr)
        return EXIT_CANCELLED
    except KeyboardInterrupt:
        print("panotopo: interrupted", file=sys.stderr)
        return EXIT_CANCELLED
    except PanotopoError as exc:
        print(f"panotopo: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:  # e.g. an output folder that cannot be written
        print(f"panotopo: error: {exc.filename or ''}: {exc.strerror or exc}".replace(": : ", ": "), file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
