"""Two recordings of one world on different days: mapped alone, and together as one site.

    python benchmarks/bench_sessions.py --family first  --seeds 0,1 --note tuning
    python benchmarks/bench_sessions.py --family second --seeds 0,1 --note "held out"

For every (route, look, seed) the day pair (``engine.synth.sessions.day_pair`` /
``engine.synth2.sessions.day_pair``: the same world, other light, other people, another
start, part of the route driven the other way) is rendered at 256x128, 1 frame/s, and each
day described with the options ``bench_families.describe_rgb`` uses (effnet-vlad at input
height 128, the method's photometric option) and ONE vocabulary for both days: day 1's own,
fixed for day 2 (``--vocabulary day1``; ``own`` describes each day with its own vocabulary,
what two separate ``panotopo describe`` runs give today: their vectors are not comparable,
see ``described``). Cached under --cache as
``sessions_<family>_<route>_<look>_s<seed>_day<k>_<vocabulary>_h128[_<photometric>].npz``, the
ground truth beside it as ``..._day<k>_poses.csv``. Then:

(a) each day is mapped alone (``engine.run.run``);
(b) both are mapped together as one site (``map_together``: ``engine.site.map_site`` on the two
    .npz files; where that cannot run, the CLI ``panotopo map A.npz B.npz -o site.graphml
    --keep-candidates`` in a subprocess, its GraphML read back with networkx).

Figures (all from node positions on the ground truth, one world frame for both days):

- shared places: node pairs across the two recordings within 1 m, grouped into places as
  ``engine.evaluate`` groups revisits (8-neighbours in the (day-1 node, day-2 node) grid: one
  stretch driven both days, either way, is one place); a place is *found* when an automatic
  loop (auto, confirmed, manual) joins two of its nodes across the days;
- loops across the days: *right* within 1 m, *between* 1-2 m (neither right nor false: the
  two views may well show the same place), *false* beyond 2 m; and the review queue's
  candidates across the days (false: beyond 2 m);
- within each recording, alone and in the site: revisits found and loops in ``engine.evaluate``'s
  band (false beyond 2 m or between temporal neighbours, 5 nodes as ``bench_families``; 1-2 m
  apart counted apart, neither right nor false);
- joined: whether the site's automatic loops join the two recordings at all.

One row per run (totals) goes to ``benchmarks/results/runs.csv`` through ``runs.append_run``
(``places`` = shared places, ``false_loops`` = loops beyond 2 m across the days plus false
loops within the recordings in the site; the within-recording figures alone and in the site
are in its notes); ``--no-record`` prints only.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_families as bf  # noqa: E402
from engine.descriptors.base import Descriptors  # noqa: E402
from engine.evaluate import FALSE_BEYOND_M, FOUND_WITHIN_M, LoopBand, loop_band  # noqa: E402
from engine.params import MapParams  # noqa: E402
from engine.poses import Poses  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EVAL_NN = bf.EVAL_NN        # temporal neighbours (nodes) never counted as revisits
RIGHT_M, FALSE_M = FOUND_WITHIN_M, FALSE_BEYOND_M  # a loop across the days: right within 1 m, false beyond 2 m
FIRST_ROUTES = ("crossing", "reverse", "offset", "loop")
FIRST_LOOKS = ("indoor", "outdoor")


@dataclass(frozen=True)
class PairCase:
    family: str
    route: str
    look: str
    seed: int

    def name(self, day: int) -> str:
        return f"sessions_{self.family}_{self.route}_{self.look}_s{self.seed}_day{day}"


def cases(family: str, seeds, routes=None, looks=None) -> list[PairCase]:
    if family == "first":
        return [PairCase("first", r, lk, s) for s in seeds for r in (routes or FIRST_ROUTES)
                for lk in (looks or FIRST_LOOKS)]
    import engine.synth2 as synth2

    return [PairCase("second", r, "second", s) for s in seeds for r in (routes or synth2.ROUTES)]


# ------------------------------------------------------------------ recordings

def _poses_csv(path: Path) -> Path:
    return path.with_name(path.name.split("_h128")[0].rsplit("_", 1)[0] + "_poses.csv")


def _save_poses(poses: Poses, path: Path) -> None:
    arr = np.stack([poses.t, poses.x, poses.y, poses.yaw], 1)
    np.savetxt(path, arr, delimiter=",", header="t,x,y,yaw", comments="", fmt="%.9g")


def _load_poses(path: Path) -> Poses:
    a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return Poses(t=a[:, 0].copy(), x=a[:, 1].copy(), y=a[:, 2].copy(), yaw=a[:, 3].copy())


def render_pair(case: PairCase):
    if case.family == "first":
        from bench_methods import case_for
        from engine.synth.sessions import day_pair

        c = case_for(case.route, case.look, case.seed)   # day 1: bench_families' disturbances
        return day_pair(case.route, case.seed, case.look, width=256, height=128, fps=1.0,
                        people=c.people, lighting_drift=c.lighting_drift, noise=c.noise)
    from engine.synth2.sessions import day_pair

    return day_pair(case.route, case.seed, width=256, fps=1.0)


VOCABULARIES = ("day1", "own")


def _describe(frames, stamps, name: str, model):
    from engine.frames import Frame
    from engine.pipeline import DescribeSettings, describe_frames

    options = {"input_height": 128, **({} if bf.PHOTOMETRIC["value"] == "none" else
                                       {"photometric": bf.PHOTOMETRIC["value"]})}
    settings = DescribeSettings(interval=1.0, options=options)
    items = (Frame(k, float(t), rgb) for k, (t, rgb) in enumerate(zip(stamps, frames)))
    t0 = time.perf_counter()
    d = describe_frames(items, len(stamps), settings, model=model, source=name)
    d.meta["bench_fps"] = len(stamps) / max(time.perf_counter() - t0, 1e-9)
    return d


def _model(vocabulary=None):
    from engine import descriptors as registry

    options = {"input_height": 128, **({} if bf.PHOTOMETRIC["value"] == "none" else
                                       {"photometric": bf.PHOTOMETRIC["value"]})}
    if vocabulary is not None:
        options["vocabulary"] = vocabulary
    return registry.get("effnet-vlad", **options)


def described(case: PairCase, cache: Path, vocabulary: str = "day1") -> list[tuple[Path, Descriptors, Poses]]:
    """Both days: (descriptors .npz, descriptors, poses), rendered and described when not cached.

    effnet-vlad pools over a vocabulary clustered from the recording itself, and the .npz
    does not keep it: two recordings described apart (``vocabulary="own"``, what two
    ``panotopo describe`` calls give) have descriptors in two different spaces. ``"day1"``
    describes day 1 with its own vocabulary and day 2 with day 1's (fixed) vocabulary, as
    ``--vocabulary`` does; both files then name that vocabulary (sha1) in their settings."""
    names = [f"{case.name(k)}_{vocabulary}" for k in (1, 2)]
    paths = [bf.cache_path(cache, n) for n in names]
    if not all(p.is_file() and _poses_csv(p).is_file() for p in paths):
        pair = render_pair(case)
        cache.mkdir(parents=True, exist_ok=True)
        model = _model()
        d1 = _describe(pair.day1.frames, pair.day1.stamps, names[0], model)
        if vocabulary == "day1":
            model = _model(np.array(model.vocabulary, copy=True))
        else:
            model = _model()
        d2 = _describe(pair.day2.frames, pair.day2.stamps, names[1], model)
        if vocabulary == "day1":   # day 1 was pooled over exactly these centres
            d1.meta["settings"] = dict(d2.meta["settings"])
        for d, path, rec in ((d1, paths[0], pair.day1), (d2, paths[1], pair.day2)):
            d.save(path)
            _save_poses(rec.poses, _poses_csv(path))
    return [(p, Descriptors.load(p), _load_poses(_poses_csv(p))) for p in paths]


# ------------------------------------------------------------------ maps, in one neutral form

@dataclass
class MapView:
    """A map's nodes (session 0/1, order within the session, stamp) and loop arcs."""

    session: np.ndarray
    order: np.ndarray
    stamp: np.ndarray
    loops: list = field(default_factory=list)   # (row a, row b, status)
    how: str = ""
    measured: list = field(default_factory=list)   # (row a, row b, distance_steps) of the loops measured


def view_of(graph, names: list[str], how: str = "") -> MapView:
    """A networkx map (a TopoMap's graph or GraphML read back) as a ``MapView``; node
    ``session`` names are matched against ``names`` (no attribute: session 0)."""
    nodes = sorted(graph.nodes, key=lambda n: int(graph.nodes[n]["index"]))
    row = {n: k for k, n in enumerate(nodes)}
    sess = np.array([names.index(str(graph.nodes[n]["session"])) if "session" in graph.nodes[n] else 0
                     for n in nodes], np.int64)
    order = np.zeros(len(nodes), np.int64)
    for s in np.unique(sess):
        order[sess == s] = np.arange(int((sess == s).sum()))
    stamp = np.array([float(graph.nodes[n]["stamp"]) for n in nodes])
    arcs = [(row[u], row[v], d) for u, v, d in graph.edges(data=True) if d.get("kind") == "loop"]
    loops = [(a, b, str(d.get("status", "auto"))) for a, b, d in arcs]
    measured = [(a, b, float(d["distance_steps"])) for a, b, d in arcs
                if d.get("distance_steps") is not None and np.isfinite(float(d["distance_steps"]))]
    return MapView(sess, order, stamp, loops, how, measured)


def map_alone(descs: Descriptors, params: MapParams) -> MapView:
    from engine.run import run

    return view_of(run(descs, params).topomap.graph, [""], "alone")


def _site_api(npz: list[Path], params: MapParams) -> Optional[MapView]:
    try:
        from engine.site import map_site
    except ImportError:
        return None
    from engine.errors import InputError

    try:
        res = map_site([str(p) for p in npz], params)
    except TypeError as err:   # the API is being written: build_map without sessions yet
        print(f"engine.site.map_site could not run ({err}); trying the CLI", file=sys.stderr)
        return None
    except InputError as err:  # e.g. .npz files described over their own vocabularies
        print(f"engine.site.map_site refused the pair: {err}", file=sys.stderr)
        return MapView(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), [], "refused")
    return view_of(res.topomap.graph, [p.name for p in npz], "engine.site")


def _site_cli(npz: list[Path], params: MapParams) -> Optional[MapView]:
    import networkx as nx

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "site.graphml"
        cmd = [sys.executable, "-m", "engine", "map", *map(str, npz), "-o", str(out), "--keep-candidates",
               "--method", params.method]
        env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
        done = subprocess.run(cmd, cwd=tmp, env=env, capture_output=True, text=True)
        if done.returncode != 0 or not out.is_file():
            print(f"panotopo map A B: {done.stderr.strip().splitlines()[-1:] or done.returncode}", file=sys.stderr)
            return None
        return view_of(nx.read_graphml(out), [p.name for p in npz], "cli")


def map_together(npz: list[Path], params: MapParams) -> Optional[MapView]:
    """The two days as one site: the site API, else the CLI; None when neither can or the
    site API refuses the pair (a line on stderr says why)."""
    view = _site_api(npz, params)
    if view is not None:
        return None if view.how == "refused" else view
    return _site_cli(npz, params)


# ------------------------------------------------------------------ scoring

FOUND = ("auto", "confirmed", "manual")


def _groups(pi: np.ndarray, pj: np.ndarray) -> np.ndarray:
    """Group label per pair: pairs 8-neighbouring in the (i, j) grid share a group."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if pi.size == 0:
        return np.zeros(0, np.int64)
    key = {(int(a), int(b)): k for k, (a, b) in enumerate(zip(pi, pj))}
    src, dst = [], []
    for (a, b), k in key.items():
        for da in (-1, 0, 1):
            for db in (-1, 0, 1):
                o = key.get((a + da, b + db))
                if o is not None:
                    src.append(k)
                    dst.append(o)
    adj = coo_matrix((np.ones(len(src), np.int8), (src, dst)), shape=(pi.size, pi.size))
    return connected_components(adj, directed=False)[1]


def positions(view: MapView, poses: list[Poses]) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.zeros(view.stamp.size), np.zeros(view.stamp.size)
    for s, p in enumerate(poses):
        m = view.session == s
        if m.any():
            x[m], y[m] = p.at(view.stamp[m])
    return x, y


def score_within(view: MapView, poses: list[Poses], s: int) -> dict:
    """Revisits found and loops within session ``s`` (``engine.evaluate``'s band: a loop of no
    revisit is false beyond 2 m or between temporal neighbours, else 1-2 m apart, "between")."""
    x, y = positions(view, poses)
    rows = np.flatnonzero(view.session == s)
    xs, ys = x[rows], y[rows]
    m = rows.size
    d2 = (xs[:, None] - xs[None]) ** 2 + (ys[:, None] - ys[None]) ** 2
    ii, jj = np.nonzero(np.triu(d2 <= (RIGHT_M + 1e-9) ** 2, k=EVAL_NN + 1))
    label = _groups(ii, jj)
    rank = {int(r): k for k, r in enumerate(rows)}
    pair_event = {(int(a), int(b)): int(g) for a, b, g in zip(ii, jj, label)}
    found, fp, between = set(), 0, 0
    for a, b, status in view.loops:
        if a not in rank or b not in rank or status not in FOUND:
            continue
        i, j = sorted((rank[a], rank[b]))
        if j - i < 2:
            continue
        if (i, j) in pair_event:
            found.add(pair_event[(i, j)])
        elif j - i > EVAL_NN and loop_band(float(np.sqrt(d2[i, j])), RIGHT_M, FALSE_M) is LoopBand.DONT_CARE:
            between += 1
        else:
            fp += 1
    return {"nodes": m, "places": int(np.unique(label).size), "found": len(found), "false": fp, "between": between}


def shared_places(view: MapView, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The node pairs across the two sessions within ``RIGHT_M``: (session-0 rows, session-1
    rows, each pair's place label; module notes)."""
    r1, r2 = np.flatnonzero(view.session == 0), np.flatnonzero(view.session == 1)
    d2 = (x[r1][:, None] - x[r2][None]) ** 2 + (y[r1][:, None] - y[r2][None]) ** 2
    ii, jj = np.nonzero(d2 <= (RIGHT_M + 1e-9) ** 2)
    return r1[ii], r2[jj], _groups(ii, jj)


def score_across(view: MapView, poses: list[Poses]) -> dict:
    """Shared places and loops across the two sessions (module notes)."""
    x, y = positions(view, poses)
    ra, rb, label = shared_places(view, x, y)
    pair_event = {(int(a), int(b)): int(g) for a, b, g in zip(ra, rb, label)}
    out = {"shared": int(np.unique(label).size), "found": 0, "right": 0, "between": 0, "false": 0,
           "queue": 0, "queue_false": 0, "with_queue": 0, "joined": False}
    found, with_queue = set(), set()
    for a, b, status in view.loops:
        if view.session[a] == view.session[b] or status == "rejected":
            continue
        a, b = (a, b) if view.session[a] == 0 else (b, a)
        dist = float(np.hypot(x[a] - x[b], y[a] - y[b]))
        event = pair_event.get((a, b))
        if status in FOUND:
            out["joined"] = True
            out[{LoopBand.TRUE: "right", LoopBand.DONT_CARE: "between",
                 LoopBand.FALSE: "false"}[loop_band(dist, RIGHT_M, FALSE_M)]] += 1
            if event is not None:
                found.add(event)
                with_queue.add(event)
        elif status == "candidate":
            out["queue"] += 1
            out["queue_false"] += int(loop_band(dist, RIGHT_M, FALSE_M) is LoopBand.FALSE)
            if event is not None:
                with_queue.add(event)
    out["found"], out["with_queue"] = len(found), len(with_queue)
    return out


# ------------------------------------------------------------------ the run

def run_case(case: PairCase, cache: Path, params: MapParams, vocabulary: str = "day1") -> dict:
    days = described(case, cache, vocabulary)
    npz = [p for p, _, _ in days]
    poses = [pz for _, _, pz in days]
    row = {"case": case, "nodes": [], "alone": [], "site": None}
    for k, (_, d, pz) in enumerate(days):
        v = map_alone(d, params)
        row["alone"].append(score_within(v, [pz], 0))
    site = map_together(npz, params)
    if site is not None:
        row["site"] = {"how": site.how, "within": [score_within(site, poses, s) for s in (0, 1)],
                       "across": score_across(site, poses)}
    return row


def _frac(a: int, b: int) -> str:
    return f"{a}/{b}"


def table(rows: list[dict]) -> str:
    head = ("| route | look | seed | nodes day 1/2 | alone: revisits found day 1, day 2 (false loops) | "
            "site: revisits found day 1, day 2 (false loops) | shared places found | with queue | "
            "across: right / 1-2 m / false | queue across (false) | joined | site by |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    tot = {"shared": 0, "found": 0, "with_queue": 0, "right": 0, "between": 0, "false": 0, "queue": 0,
           "queue_false": 0, "joined": 0}
    for r in rows:
        c, a = r["case"], r["alone"]
        alone = f"{_frac(a[0]['found'], a[0]['places'])}, {_frac(a[1]['found'], a[1]['places'])} ({a[0]['false'] + a[1]['false']})"
        if r["site"] is None:
            lines.append(f"| {c.route} | {c.look} | {c.seed} | {a[0]['nodes']}/{a[1]['nodes']} | {alone} | "
                         f"- | - | - | - | - | - | not available |")
            continue
        w, x = r["site"]["within"], r["site"]["across"]
        for k in tot:
            tot[k] += int(x[k])
        lines.append(
            f"| {c.route} | {c.look} | {c.seed} | {w[0]['nodes']}/{w[1]['nodes']} | {alone} | "
            f"{_frac(w[0]['found'], w[0]['places'])}, {_frac(w[1]['found'], w[1]['places'])} "
            f"({w[0]['false'] + w[1]['false']}) | {_frac(x['found'], x['shared'])} | "
            f"{_frac(x['with_queue'], x['shared'])} | {x['right']} / {x['between']} / {x['false']} | "
            f"{x['queue']} ({x['queue_false']}) | {'yes' if x['joined'] else 'no'} | {r['site']['how']} |")
    return "\n".join(lines)


def totals(rows: list[dict]) -> dict:
    t = {"pairs": len(rows), "mapped": 0, "shared": 0, "found": 0, "with_queue": 0, "right": 0, "between": 0,
         "false_across": 0, "queue": 0, "queue_false": 0, "joined": 0}
    for key in ("alone", "site"):
        t[key] = {"places": 0, "found": 0, "false": 0, "between": 0}
    for r in rows:
        if r["site"] is None:
            continue
        t["mapped"] += 1
        for key, within in (("alone", r["alone"]), ("site", r["site"]["within"])):
            for w in within:
                for k in t[key]:
                    t[key][k] += w[k]
        x = r["site"]["across"]
        t["shared"] += x["shared"]
        t["found"] += x["found"]
        t["with_queue"] += x["with_queue"]
        t["right"] += x["right"]
        t["between"] += x["between"]
        t["false_across"] += x["false"]
        t["queue"] += x["queue"]
        t["queue_false"] += x["queue_false"]
        t["joined"] += int(x["joined"])
    return t


def summary(t: dict) -> str:
    a, s = t["alone"], t["site"]
    return (f"{t['mapped']}/{t['pairs']} day pairs mapped as a site: shared places found {t['found']}/{t['shared']} "
            f"(with the queue {t['with_queue']}), loops across the days right {t['right']}, 1-2 m {t['between']}, "
            f"false {t['false_across']}; queue across {t['queue']} ({t['queue_false']} false); joined "
            f"{t['joined']}/{t['mapped']}. Within the recordings: alone {a['found']}/{a['places']} revisits, "
            f"{a['false']} false loops ({a['between']} 1-2 m); in the site {s['found']}/{s['places']}, "
            f"{s['false']} false loops ({s['between']} 1-2 m).")


def record(t: dict, family: str, seeds, method: str, note: str) -> None:
    from runs import RUNS, append_run

    a, s = t["alone"], t["site"]
    notes = (f"bench_sessions.py: two days of one world mapped as one site ({t['mapped']}/{t['pairs']} pairs); "
             f"loops across 1-2 m {t['between']}, beyond 2 m {t['false_across']}; within the recordings alone "
             f"{a['found']}/{a['places']} revisits {a['false']} false ({a['between']} 1-2 m), in the site "
             f"{s['found']}/{s['places']} {s['false']} false ({s['between']} 1-2 m); joined {t['joined']}/{t['mapped']}")
    append_run({"family": family, "seeds": seeds, "method": method, "runs": 2 * t["mapped"],
                "places": t["shared"], "places_found": t["found"],
                "false_loops": t["false_across"] + s["false"], "with_queue": t["with_queue"],
                "queue": t["queue"], "false_in_queue": t["queue_false"],
                "notes": "; ".join(filter(None, (note, notes)))})
    print(f"appended 1 row to {RUNS}", file=sys.stderr)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", choices=("first", "second"), required=True)
    ap.add_argument("--seeds", default="0,1", help="comma-separated seeds")
    ap.add_argument("--routes", help="comma-separated routes (default: the family's)")
    ap.add_argument("--looks", help="first family: comma-separated looks (default: indoor,outdoor)")
    ap.add_argument("--method", default=MapParams().method)
    ap.add_argument("--cache", default="/tmp/panotopo-sessions", help="descriptor cache folder")
    ap.add_argument("--vocabulary", choices=VOCABULARIES, default="day1",
                    help="effnet-vlad vocabulary: day1 (day 2 pooled over day 1's) or own (each day its own)")
    ap.add_argument("--note", default="", help="notes column of the row appended to runs.csv")
    ap.add_argument("--no-record", action="store_true", help="print the table only")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    split = (lambda v: [x for x in v.split(",") if x] if v else None)
    params = MapParams(method=args.method)
    bf.PHOTOMETRIC["value"] = bf.photometric_for(args.method)
    rows = []
    for case in cases(args.family, seeds, split(args.routes), split(args.looks)):
        t0 = time.perf_counter()
        rows.append(run_case(case, Path(args.cache), params, args.vocabulary))
        x = (rows[-1]["site"] or {}).get("across", {})
        print(f"{case.name(1)[:-5]}: {time.perf_counter() - t0:.1f} s; shared places found "
              f"{x.get('found', '-')}/{x.get('shared', '-')}, across right/1-2 m/false "
              f"{x.get('right', '-')}/{x.get('between', '-')}/{x.get('false', '-')}", file=sys.stderr, flush=True)
    t = totals(rows)
    print(table(rows) + "\n\n" + summary(t))
    if not args.no_record and t["mapped"]:
        record(t, args.family, seeds, args.method, args.note)


if __name__ == "__main__":
    main()
