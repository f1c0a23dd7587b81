"""Methods benchmark on synthetic routes: the harness shared by benchmarks/ and tests/.

A benchmark case is one synthetic recording (route, look, seed, people, lighting,
noise). Each recording is rendered once, described once per panorama-shift setting and
once more per describe option a method asks for (``engine.params.METHOD_DESCRIBE_OPTIONS``;
cached as .npz when a cache folder is given), and then mapped by every method from the
descriptors it asks for; each map is scored against the ground-truth poses with
``engine.evaluate`` (the paper's TP/FP/TN/FN plus revisit events) and with the project's
don't-care band (``engine.evaluate.evaluate_band``: loops within 1 m true, 1-2 m neither right
nor false, beyond 2 m or between temporal neighbours false; its places found / revisited are
the revisit events above, ``events_found`` / ``events_total``).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Iterable, Optional

import numpy as np

from engine.descriptors.base import Descriptors
from engine.evaluate import evaluate, evaluate_band
from engine.frames import Frame
from engine.params import METHODS, MapParams
from engine.pipeline import DescribeSettings, describe_frames, method_settings
from engine.run import run
from engine.poses import Poses
from engine.synth import make_recording
from engine.synth.routes import make_route

# Recordings are rendered at one frame per second, so sampling every 1.0 s keeps them all.
FPS = 1.0


@dataclass(frozen=True)
class Case:
    route: str
    look: str
    seed: int = 0
    people: int = 0
    lighting_drift: float = 0.0
    noise: float = 0.0
    width: int = 256

    @property
    def name(self) -> str:
        extra = f"_p{self.people}_l{self.lighting_drift:g}_n{self.noise:g}" if (
            self.people or self.lighting_drift or self.noise) else ""
        return f"{self.route}_{self.look}_s{self.seed}_w{self.width}{extra}"

    def poses(self) -> Poses:
        """Ground truth without rendering (the trajectory alone is cheap)."""
        tr = make_route(self.route, self.look, self.seed, fps=FPS, people=self.people,
                        lighting_drift=self.lighting_drift, noise=self.noise).trajectory
        return Poses(t=tr.t.astype(np.float64), x=tr.x.copy(), y=tr.y.copy(), yaw=tr.yaw.copy())


@dataclass
class Described:
    case: Case
    by_shift: dict            # {True: Descriptors, False: Descriptors}, plain (no method's options)
    poses: Poses
    frames_per_second: dict = field(default_factory=dict)  # extraction speed per key of by_shift / by_need
    by_need: dict = field(default_factory=dict)  # MapParams.describe_needs -> Descriptors with a method's options

    def for_method(self, method: str) -> tuple:
        """(descriptors, key) ``method`` is mapped on: those described with its describe options
        (``MapParams.describe_needs``) where ``describe_case`` made them, else the plain ones of
        its panorama shift."""
        need = MapParams(method=method).describe_needs
        if need in self.by_need:
            return self.by_need[need], need
        return self.by_shift[need[0]], need[0]


def describe_case(case: Case, shifts: Iterable[bool] = (True, False), input_height: int = 128,
                  descriptor: str = "effnet-vlad", cache_dir: Optional[Path] = None,
                  methods: Iterable[str] = ()) -> Described:
    """Render ``case`` and describe it once per shift setting, plainly, and once more for each
    distinct describe need of ``methods`` that asks for options of its own
    (``engine.pipeline.method_settings``, e.g. verified's standardised effnet-vlad); cached
    under ``cache_dir``."""
    base = DescribeSettings(descriptor=descriptor, interval=1.0 / FPS, options={"input_height": input_height})
    jobs: dict = {bool(shift): replace(base, shift=bool(shift)) for shift in shifts}
    for method in methods:
        settings = method_settings(MapParams(method=method), base)
        plain = settings.options == base.options
        jobs.setdefault(settings.shift if plain else MapParams(method=method).describe_needs, settings)
    described: dict = {}
    fps: dict = {}
    rec = None
    for key, settings in jobs.items():
        path = None
        if cache_dir is not None:
            extra = "".join(f"_{v}" for k, v in sorted(settings.options.items()) if k != "input_height")
            path = Path(cache_dir) / (f"{case.name}_{descriptor}_h{input_height}_"
                                      f"{'shift' if settings.shift else 'noshift'}{extra}.npz")
            if path.is_file():
                d = Descriptors.load(path)
                described[key] = d
                fps[key] = float(d.meta.get("bench_fps", 0.0))
                continue
        if rec is None:
            rec = make_recording(case.route, case.look, case.seed, width=case.width, height=case.width // 2,
                                 fps=FPS, people=case.people, lighting_drift=case.lighting_drift,
                                 noise=case.noise)
        frames = (Frame(k, float(t), rgb) for k, (t, rgb) in enumerate(zip(rec.stamps, rec.frames)))
        t0 = time.perf_counter()
        d = describe_frames(frames, len(rec), settings, source=case.name)
        fps[key] = len(rec) / max(time.perf_counter() - t0, 1e-9)
        d.meta["bench_fps"] = fps[key]
        described[key] = d
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            d.save(path)
    by_shift = {k: d for k, d in described.items() if isinstance(k, bool)}
    by_need = {k: d for k, d in described.items() if not isinstance(k, bool)}
    return Described(case, by_shift, case.poses(), fps, by_need)


@dataclass
class Row:
    route: str
    look: str
    seed: int
    method: str
    nodes: int
    tp: int
    fp: int
    tn: int
    fn: int
    precision: float
    recall: float
    accuracy: float
    f1: float
    events_found: int
    events_total: int
    extraction_fps: float
    people: int = 0
    family: str = "synth"
    candidates: int = 0              # undecided candidates in the map (two-tier methods)
    false_candidates: int = 0        # of them, not the same place (or temporal neighbours)
    events_with_candidates: int = 0  # revisit events found by an auto loop or a candidate
    event_closest: tuple = ()        # per event: closest same-place pair, metres
    event_found: tuple = ()          # per event: found by an automatic loop
    event_span: tuple = ()           # per event: the most nodes between its two visits
    # The project's band (engine.evaluate.evaluate_band), automatic loops: within 1 m, 1-2 m
    # (neither right nor false), false (beyond 2 m or temporal neighbours); and the review
    # queue's candidates that the band calls false.
    true_loops: int = 0
    dont_care_loops: int = 0
    band_false_loops: int = 0
    band_false_candidates: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


def evaluate_methods(described: Described, methods: Iterable[str] = METHODS,
                     params: Optional[dict] = None, eval_nn: int = 5) -> list[Row]:
    """Map ``described`` with every method and score each map.

    ``params`` maps a method to the MapParams used for it (default ``MapParams(method=m)``).
    ``eval_nn``: temporal neighbours (in nodes) never counted as positives, the same for
    every method so the tables compare like with like.
    """
    rows = []
    case = described.case
    for method in methods:
        p = (params or {}).get(method) or MapParams()
        p = replace(p, method=method)
        descs, key = described.for_method(method)
        topomap = run(descs, p).topomap
        rows.append(score_map(topomap, described.poses, case, method, eval_nn,
                              float(described.frames_per_second.get(key, 0.0))))
    return rows


def score_map(topomap, poses: Poses, case, method: str, eval_nn: int = 5, fps: float = 0.0) -> Row:
    """One results row: the exported map's metrics, plus what the candidate tier adds."""
    ev = evaluate(topomap, poses, neighbor_node_num=eval_nn)
    with_cand = evaluate(topomap, poses, neighbor_node_num=eval_nn, include_candidates=True)
    cands = len(topomap.loops(("candidate",)))
    band = evaluate_band(topomap, poses, neighbor_node_num=eval_nn)
    band_with_cand = evaluate_band(topomap, poses, neighbor_node_num=eval_nn, include_candidates=True)
    return Row(case.route, case.look, case.seed, method, topomap.node_count, ev.tp, ev.fp,
               ev.tn, ev.fn, ev.precision, ev.recall, ev.accuracy, ev.f1, ev.events_found,
               ev.events_total, fps, getattr(case, "people", 0), getattr(case, "family", "synth"),
               cands, with_cand.fp - ev.fp, with_cand.events_found,
               tuple(ev.event_closest), tuple(ev.event_found), tuple(ev.event_span),
               band.true_loops, band.dont_care_loops, band.false_loops,
               band_with_cand.false_loops - band.false_loops)


PAPER_METHODS = ("simple", "shift-simple", "ours")


def calibrated_params(described: Described, methods: Iterable[str] = METHODS) -> dict:
    """MapParams per method: the paper's three share thresholds calibrated from the
    recording's shifted descriptors (``calibrate.paper_thresholds``); others use their defaults."""
    from engine.calibrate import paper_thresholds

    th = paper_thresholds(described.by_shift[True].vectors)
    return {m: (MapParams(**th) if m in PAPER_METHODS else MapParams()) for m in methods}


def evaluate_route(route: str, look: str, seed: int = 0, methods: Iterable[str] = METHODS,
                   cache_dir: Optional[Path] = None, input_height: int = 128, width: int = 256,
                   params: "Optional[dict] | str" = "calibrated", **case_options) -> list[Row]:
    """Render, describe and map one route with every method: rows of the results table.

    ``params``: MapParams per method, None for every method's defaults, or "calibrated"
    (``calibrated_params``)."""
    methods = tuple(methods)
    case = Case(route, look, seed, width=width, **case_options)
    shifts = sorted({m != "simple" for m in methods} | {True}, reverse=True)
    described = describe_case(case, shifts, input_height=input_height, cache_dir=cache_dir, methods=methods)
    if params == "calibrated":
        params = calibrated_params(described, methods)
    return evaluate_methods(described, methods, params)


def sum_rows(rows: list[Row], method: str) -> dict:
    """Totals over rows of one method (pair counts, events) with ratios recomputed."""
    sel = [r for r in rows if r.method == method]
    tot = {k: sum(getattr(r, k) for r in sel) for k in ("tp", "fp", "tn", "fn", "events_found", "events_total",
                                                        "candidates", "false_candidates",
                                                        "events_with_candidates", "true_loops",
                                                        "dont_care_loops", "band_false_loops",
                                                        "band_false_candidates")}
    tp, fp, fn = tot["tp"], tot["fp"], tot["fn"]
    tot["precision"] = tp / (tp + fp) if tp + fp else 0.0
    tot["recall"] = tp / (tp + fn) if tp + fn else 0.0
    tot["f1"] = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 0.0
    tot["runs"] = len(sel)
    return tot


def summary_table(rows: list[Row], methods, routes) -> str:
    """Totals per route type (and "all") and method: TP, false loops, revisit events found,
    precision, recall, F1."""
    lines = ["| route | method | runs | TP | false loops | events found | precision | recall | F1 |",
             "|---|---|---|---|---|---|---|---|---|"]
    for route in tuple(routes) + ("all",):
        sel = rows if route == "all" else [r for r in rows if r.route == route]
        for m in methods:
            t = sum_rows(sel, m)
            lines.append(f"| {route} | {m} | {t['runs']} | {t['tp']} | {t['fp']} | "
                         f"{t['events_found']}/{t['events_total']} | {t['precision']:.3f} | {t['recall']:.3f} "
                         f"| {t['f1']:.3f} |")
    return "\n".join(lines)


def markdown_table(rows: list[Row]) -> str:
    """Rows as a Markdown table in the layout of the paper's Tables II-V."""
    head = ("| route | look | seed | method | nodes | TP | FP | TN | FN | precision | recall | "
            "accuracy | F1 | events | extraction fps |")
    lines = [head, "|" + "---|" * 15]
    for r in rows:
        lines.append(f"| {r.route} | {r.look} | {r.seed} | {r.method} | {r.nodes} | {r.tp} | {r.fp} | "
                     f"{r.tn} | {r.fn} | {r.precision:.3f} | {r.recall:.3f} | {r.accuracy:.4f} | "
                     f"{r.f1:.3f} | {r.events_found}/{r.events_total} | {r.extraction_fps:.1f} |")
    return "\n".join(lines)


def rows_json(rows: list[Row]) -> str:
    return json.dumps([r.as_dict() for r in rows], indent=1)


def random_walk_descriptors(n: int, d: int = 1024, seed: int = 0, revisit_share: float = 0.3,
                            noise: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """(n, d) L2-normalised descriptors that look like a recording, and where they revisit.

    A smooth walk on the unit sphere (a heading with momentum, consecutive cosine about
    0.97, about 20 steps to forget a place) around a shared mean direction (so unrelated
    places still have cosine about 0.3, as real descriptors do). About ``revisit_share``
    of the rows are stretches (20 to 300 rows) of earlier rows driven again forward or in
    reverse, each row a noisy copy (``noise`` 0.6: cosine about 0.9 to its original);
    the walk then goes on from there. ``origin[i]`` is the earlier row that row i
    revisits, -1 for new ground. For benchmarks and tests of retrieval at any n.
    """
    rng = np.random.default_rng(seed)
    walk = np.empty((n, d), np.float32)
    origin = np.full(n, -1, np.int64)
    mean_dir = rng.standard_normal(d).astype(np.float32)
    mean_dir /= np.linalg.norm(mean_dir)
    x = rng.standard_normal(d).astype(np.float32)
    x /= np.linalg.norm(x)
    heading = rng.standard_normal(d).astype(np.float32) / np.sqrt(d)
    i = 0
    while i < n:
        if i > 400 and rng.random() < revisit_share / (1 - revisit_share) * 100 / 160:
            length = int(min(n - i, rng.integers(20, 300)))
            sign = 1 if rng.random() < 0.5 else -1
            start = int(rng.integers(0, i - length)) if i - length > 0 else 0
            src = start + np.arange(length) if sign == 1 else start + length - 1 - np.arange(length)
            src = np.clip(src, 0, i - 1)
            noisy = walk[src] + noise * rng.standard_normal((length, d)).astype(np.float32) / np.sqrt(d)
            walk[i:i + length] = noisy / np.linalg.norm(noisy, axis=1, keepdims=True)
            origin[i:i + length] = src
            x = walk[src[-1]].copy()
            i += length
        length = int(min(n - i, rng.integers(50, 150)))
        g = rng.standard_normal((length, d)).astype(np.float32) / np.sqrt(d)
        for t in range(length):
            heading = 0.8 * heading + 0.6 * g[t]
            heading /= np.linalg.norm(heading)
            x = x + 0.25 * heading
            x /= np.linalg.norm(x)
            walk[i + t] = x
        i += length
    for r0 in range(0, n, 8192):   # in place, a block at a time: no second (n, d) copy
        block = walk[r0:r0 + 8192]
        block += 0.65 * mean_dir[None, :]
        block /= np.linalg.norm(block, axis=1, keepdims=True)
    return walk, origin
