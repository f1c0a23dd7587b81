"""The panotopo command end to end on a small synthetic recording in every input format."""

import json
import subprocess
import sys
from pathlib import Path

import igraph
import networkx as nx
import numpy as np
import pytest

from engine.cli import main
from engine.synth import make_recording, write_recording

FAST = ["--input-height", "64", "-q"]  # a small descriptor input keeps the suite quick


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """The first 30 s of the route, in every format: what the format, option and cache tests need
    (every frame of it is described, once per test; the whole route is ``full_recording``)."""
    out = tmp_path_factory.mktemp("rec")
    rec = make_recording("reverse", look="indoor", seed=3, width=256, height=128, fps=2.0, max_frames=60)
    return rec, write_recording(rec, out)


@pytest.fixture(scope="module")
def full_recording(tmp_path_factory):
    """The whole ``reverse`` route (it comes back along the corridor), as a video and its poses."""
    out = tmp_path_factory.mktemp("full")
    rec = make_recording("reverse", look="indoor", seed=3, width=256, height=128, fps=2.0)
    return rec, write_recording(rec, out, formats=("video", "poses"))


@pytest.fixture()
def cache_dir(tmp_path):
    return ["--cache-dir", str(tmp_path / "cache")]


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


NODE_TYPES = {"index": int, "frame": int, "stamp": float, "shift": int, "label": str}
EDGE_TYPES = {"kind": str, "similarity": float, "status": str}


def check_contract(path: Path, method: str) -> nx.Graph:
    g = nx.read_graphml(path)
    assert g.graph["generator"].startswith("panotopo")
    assert g.graph["method"] == method
    for key in ("source", "descriptor", "node_sim_th", "loop_sim_th", "window_size", "count_th",
                "neighbor_node_num"):
        assert key in g.graph, key
    assert g.number_of_nodes() > 3
    for k, (node, attrs) in enumerate(sorted(g.nodes(data=True), key=lambda na: na[1]["index"])):
        assert node == f"n{k}" and attrs["index"] == k
        for key, typ in NODE_TYPES.items():
            assert isinstance(attrs[key], typ), (key, attrs[key])
    kinds = {a["kind"] for _, _, a in g.edges(data=True)}
    assert "sequential" in kinds
    for _, _, attrs in g.edges(data=True):
        for key, typ in EDGE_TYPES.items():
            assert isinstance(attrs[key], typ), (key, attrs[key])
        assert attrs["status"] in ("auto", "confirmed", "manual")
    # An independent reader agrees on the size.
    ig = igraph.Graph.Read_GraphML(str(path))
    assert ig.vcount() == g.number_of_nodes() and ig.ecount() == g.number_of_edges()
    return g


@pytest.mark.parametrize("fmt", ["video", "ros1", "ros2-sqlite3", "ros2-mcap", "folder"])
def test_map_every_input_format(recording, fmt, tmp_path, cache_dir, capsys):
    rec, files = recording
    out = tmp_path / "map.graphml"
    code, _, err = run_cli(capsys, "map", files[fmt], "-o", out, *FAST, *cache_dir)
    assert code == 0, err
    g = check_contract(out, "ours" if "ours" in g_methods() else g_methods()[0])
    # Node stamps are on the recording's clock and frames are real source frames.
    stamps = sorted(a["stamp"] for _, a in g.nodes(data=True))
    assert 0.0 <= stamps[0] < 1.0 and stamps[-1] <= rec.stamps[-1] + 1e-6
    assert max(a["frame"] for _, a in g.nodes(data=True)) < len(rec)


def g_methods():
    from engine.params import MapParams
    return [MapParams().method]


def test_describe_then_map_from_npz_gives_the_same_map(recording, tmp_path, cache_dir, capsys):
    _, files = recording
    npz = tmp_path / "d.npz"
    code, _, err = run_cli(capsys, "describe", files["video"], "-o", npz, "--method", "ours", *FAST, *cache_dir)
    assert code == 0, err
    with np.load(npz) as z:
        assert z["stamps"].dtype == np.float64 and z["frames"].dtype == np.int64
        assert z["shifts"].dtype == np.int64 and z["descriptors"].dtype == np.float32
        norms = np.linalg.norm(z["descriptors"], axis=1)
        assert np.allclose(norms, 1.0, atol=1e-4)
        assert json.loads(str(z["meta"]))["descriptor"] == "effnet-vlad"
        assert z["shifts"].max() > 0  # the panorama shift was applied
    a, b = tmp_path / "a.graphml", tmp_path / "b.graphml"
    for src, out in ((npz, a), (files["video"], b)):
        code, _, err = run_cli(capsys, "map", src, "-o", out, "--method", "ours", *FAST, *cache_dir)
        assert code == 0, err
    ga, gb = nx.read_graphml(a), nx.read_graphml(b)
    assert sorted(ga.nodes) == sorted(gb.nodes)
    assert sorted(map(sorted, ga.edges)) == sorted(map(sorted, gb.edges))


def test_photometric_option_reaches_the_descriptor_and_its_cache_key(recording, tmp_path, cache_dir, capsys):
    # The option is a descriptor setting: it is written into the file's meta, and a cached
    # description made without it is not reused for it (the cache key covers every setting).
    _, files = recording
    # (--method ours: a method that asks for no photometric option of its own.)
    plain, standardised = tmp_path / "plain.npz", tmp_path / "std.npz"
    assert run_cli(capsys, "describe", files["video"], "-o", plain, "--method", "ours", *FAST, *cache_dir)[0] == 0
    code, _, err = run_cli(capsys, "describe", files["video"], "-o", standardised, "--method", "ours",
                           "--photometric", "standardise", *FAST, *cache_dir)
    assert code == 0, err
    with np.load(plain) as a, np.load(standardised) as b:
        settings = [json.loads(str(z["meta"]))["settings"] for z in (a, b)]
        assert "photometric" not in settings[0] and settings[1]["photometric"] == "standardise"
        assert not np.allclose(a["descriptors"], b["descriptors"])


def _cached(cache: Path) -> list:
    """Descriptors in a descriptor cache folder (one .npz per key)."""
    from engine.descriptors.base import Descriptors

    return [Descriptors.load(p) for p in sorted(cache.rglob("*.npz"))]


def _photometric(descs) -> str:
    return descs.meta["settings"].get("photometric", "none")


@pytest.mark.parametrize("argv, expected", [
    ([], "standardise"),                                                    # verified, the default
    (["--method", "ours"], "none"),                                         # the paper's: plain
    (["--method", "verified", "--photometric", "none"], "none"),           # the user's choice wins
    (["--method", "ours", "--photometric", "standardise"], "standardise"),
])
def test_map_describes_as_its_method_asks(recording, tmp_path, capsys, argv, expected):
    _, files = recording
    cache = tmp_path / "cache"
    code, _, err = run_cli(capsys, "map", files["video"], "-o", tmp_path / "m.graphml", *argv, *FAST,
                           "--cache-dir", cache)
    assert code == 0, err
    (descs,) = _cached(cache)
    assert descs.meta["descriptor"] == "effnet-vlad" and descs.meta["shift"] is True
    assert _photometric(descs) == expected


def test_describe_then_map_uses_the_descriptors_map_alone_would(recording, tmp_path, cache_dir, capsys):
    # describe follows the default method as map does: map of the recording then finds describe's
    # descriptors in the cache (same settings, same key) instead of describing anew.
    _, files = recording
    cache = Path(cache_dir[1])
    npz, plain = tmp_path / "d.npz", tmp_path / "plain.npz"
    assert run_cli(capsys, "describe", files["video"], "-o", npz, *FAST, *cache_dir)[0] == 0
    assert run_cli(capsys, "map", files["video"], "-o", tmp_path / "m.graphml", *FAST, *cache_dir)[0] == 0
    (cached,) = _cached(cache)
    with np.load(npz) as z:
        meta = json.loads(str(z["meta"]))
    assert meta["settings"] == cached.meta["settings"] and meta["shift"] == cached.meta["shift"]
    assert _photometric(cached) == "standardise"
    a, b = tmp_path / "a.graphml", tmp_path / "b.graphml"
    assert run_cli(capsys, "map", npz, "-o", a, "-q")[0] == 0
    assert run_cli(capsys, "map", files["video"], "-o", b, *FAST, *cache_dir)[0] == 0
    ga, gb = nx.read_graphml(a), nx.read_graphml(b)
    assert sorted(ga.nodes) == sorted(gb.nodes) and sorted(map(sorted, ga.edges)) == sorted(map(sorted, gb.edges))
    # describe --method ours describes plainly; --no-shift still wins over the method's shift.
    assert run_cli(capsys, "describe", files["video"], "-o", plain, "--method", "ours", *FAST, *cache_dir)[0] == 0
    with np.load(plain) as z:
        meta = json.loads(str(z["meta"]))
    assert "photometric" not in meta["settings"] and meta["shift"] is True
    unshifted = tmp_path / "unshifted.npz"
    assert run_cli(capsys, "describe", files["video"], "-o", unshifted, "--no-shift", *FAST, *cache_dir)[0] == 0
    with np.load(unshifted) as z:
        meta = json.loads(str(z["meta"]))
        assert meta["shift"] is False and not z["shifts"].any()
    assert meta["settings"]["photometric"] == "standardise"


def test_auto_thresholds_calibrate_what_the_user_left_unset(recording, tmp_path, cache_dir, capsys):
    from engine.calibrate import paper_thresholds
    from engine.descriptors.base import Descriptors

    _, files = recording
    npz = tmp_path / "d.npz"
    assert run_cli(capsys, "describe", files["video"], "-o", npz, *FAST, *cache_dir)[0] == 0
    expected = paper_thresholds(Descriptors.load(npz).vectors, 5)
    auto, mixed = tmp_path / "auto.graphml", tmp_path / "mixed.graphml"
    assert run_cli(capsys, "map", npz, "-o", auto, "--method", "ours", "--auto-thresholds", "-q")[0] == 0
    assert run_cli(capsys, "map", npz, "-o", mixed, "--method", "ours", "--auto-thresholds",
                   "--loop-sim-th", "0.91", "-q")[0] == 0
    g = igraph.Graph.Read_GraphML(str(auto))
    assert g["node_sim_th"] == pytest.approx(expected["node_sim_th"], abs=1e-6)
    assert g["loop_sim_th"] == pytest.approx(expected["loop_sim_th"], abs=1e-6)
    g = igraph.Graph.Read_GraphML(str(mixed))
    assert g["loop_sim_th"] == pytest.approx(0.91)            # given by the user: kept
    assert g["node_sim_th"] == pytest.approx(expected["node_sim_th"], abs=1e-6)


def test_no_shift_descriptors_have_zero_shifts(recording, tmp_path, cache_dir, capsys):
    _, files = recording
    npz = tmp_path / "d.npz"
    code, _, err = run_cli(capsys, "describe", files["ros1"], "-o", npz, "--no-shift", *FAST, *cache_dir)
    assert code == 0, err
    with np.load(npz) as z:
        assert not z["shifts"].any()


def test_map_with_poses_then_eval_json(full_recording, tmp_path, cache_dir, capsys):
    rec, files = full_recording
    out, plot = tmp_path / "m.graphml", tmp_path / "m.png"
    code, _, err = run_cli(capsys, "map", files["video"], "-o", out, "--poses", files["poses"],
                           "--plot", plot, "--method", "shift-simple", *FAST, *cache_dir)
    assert code == 0, err
    g = nx.read_graphml(out)
    assert all(isinstance(a["x"], float) and isinstance(a["y"], float) for _, a in g.nodes(data=True))
    assert plot.stat().st_size > 10_000
    code, text, err = run_cli(capsys, "eval", out, "--poses", files["poses"], "--json")
    assert code == 0, err
    metrics = json.loads(text)
    m = g.number_of_nodes()
    # Every unordered pair except the path arcs is counted exactly once.
    assert metrics["tp"] + metrics["fp"] + metrics["tn"] + metrics["fn"] == (m - 1) * (m - 2) // 2
    loops = sum(1 for _, _, a in g.edges(data=True) if a["kind"] == "loop")
    assert metrics["tp"] + metrics["fp"] == loops
    # The reverse route comes back along the corridor: some same-place pairs exist.
    assert metrics["tp"] + metrics["fn"] > 0


def test_demo_writes_recording_map_and_plot(tmp_path, capsys):
    out = tmp_path / "demo"
    code, text, err = run_cli(capsys, "demo", "--out", out, "--width", "256", "--input-height", "64")
    assert code == 0, err
    for name in ("demo.mp4", "demo.bag", "poses.csv", "demo.graphml", "demo_map.png"):
        assert (out / name).exists(), name
    assert (out / "demo_ros2_sqlite3").is_dir() and (out / "demo_ros2_mcap").is_dir()
    assert "precision" in text and "demo.graphml" in text
    g = nx.read_graphml(out / "demo.graphml")
    assert all("x" in a for _, a in g.nodes(data=True))
    _demo_output_is_small_and_named(out, text, width=256)


def _demo_output_is_small_and_named(out, text: str, width: int) -> None:
    """Issue 14, defect 13: the demo wrote 630 MB of raw-image bags into an unnamed folder."""
    from engine.sources import list_image_topics, open_recording

    assert str(out.resolve()) in text                 # the folder is named in full
    counts = []
    for bag in (out / "demo.bag", out / "demo_ros2_sqlite3", out / "demo_ros2_mcap"):
        topics = list_image_topics(bag)
        assert topics and all(msgtype.endswith("CompressedImage") for _, msgtype, _ in topics)
        counts.append(topics[0][2])
        source = open_recording(bag)
        assert source.frame_at(0).rgb.shape[:2] == (width // 2, width)
        source.close()
    raw_bag = counts[0] * width * (width // 2) * 3
    written = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    assert written < raw_bag                          # everything weighs less than one raw-image bag


def test_the_default_demo_folder_is_git_ignored():
    ignored = (Path(__file__).resolve().parent.parent / ".gitignore").read_text().split()
    assert "/panotopo-demo/" in ignored


@pytest.mark.parametrize("argv, reason", [
    (["map", "{missing}", "-o", "{out}"], "no such file"),
    (["map", "{text}", "-o", "{out}"], ""),
    (["map", "{video}", "-o", "{out}", "--descriptor", "nope"], "unknown descriptor"),
    (["map", "{video}", "-o", "{out}", "--topic", "/nope"], ""),
    (["eval", "{text}", "--poses", "{poses}"], ""),
    (["map", "{ros1}", "-o", "{out}", "--topic", "/nope"], "/nope"),
])
def test_bad_input_is_one_line_and_nonzero(recording, tmp_path, argv, reason, capsys):
    _, files = recording
    text = tmp_path / "notes.mp4"
    text.write_text("this is not a video\n")
    subst = {"missing": tmp_path / "missing.mp4", "out": tmp_path / "o.graphml", "text": text,
             "video": files["video"], "poses": files["poses"], "ros1": files["ros1"]}
    args = [a.format(**{k: str(v) for k, v in subst.items()}) for a in argv]
    code, _, err = run_cli(capsys, *args)
    assert code != 0
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("panotopo: error:"), err
    assert reason.lower() in lines[0].lower()
    assert "Traceback" not in err


def test_real_process_exit_status_and_no_traceback(tmp_path):
    out = subprocess.run([sys.executable, "-m", "engine", "map", str(tmp_path / "nothing.bag"),
                          "-o", str(tmp_path / "x.graphml")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "no such file" in out.stderr.lower()


def test_a_broken_video_gives_only_our_line_on_stderr(tmp_path):
    """Not even FFmpeg's own complaint about the container precedes our message."""
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"\x00\x00\x00\x18ftypisom" + bytes(3000))
    out = subprocess.run([sys.executable, "-m", "engine", "map", str(bad), "-o", str(tmp_path / "x.graphml")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("panotopo: error:") and "broken.mp4" in lines[0]


def test_undefined_metrics_print_na_not_zero():
    """Issue 14, defect 14: no detections and no positives printed precision/recall 0.000."""
    from engine.cli import _evaluation_dict, _evaluation_lines
    from engine.evaluate import evaluate
    from engine.graph import TopoMap

    g = nx.Graph()
    for k in range(12):  # a straight walk, no loop arcs: nothing detected, no place seen twice
        g.add_node(f"n{k}", index=k, frame=k, stamp=float(k), shift=0, label="", x=float(k), y=0.0)
    ev = evaluate(TopoMap(g, {"neighbor_node_num": 2}))
    text = _evaluation_lines(ev)
    assert "precision n/a" in text and "recall n/a" in text and "F1 n/a" in text
    assert "accuracy 1.000" in text
    assert set(_evaluation_dict(ev)["undefined"]) == {"precision", "recall", "f1"}


def test_progress_bar_names_stages_without_a_count_of_nothing(capsys):
    """Issue 43 item 20: "building the map: 0frame" was printed twice; the loop search
    ("ours") had no progress at all. A stage of unknown size shows its name once; the loop
    search counts its tiles."""
    from engine.cli import _Bar
    from engine.loops.paper import OURS_STAGE

    bar = _Bar(quiet=False)
    bar(0, 0, "building the map")
    bar(0, 0, "building the map")
    for done in range(5):
        bar(done, 4, OURS_STAGE)
    bar.close()
    err = capsys.readouterr().err
    assert "0frame" not in err and "frame" not in err
    assert err.count("building the map") == 1
    assert "4/4" in err and "tile" in err
