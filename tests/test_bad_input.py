"""Every bad input of issue 16 (findings 10, 11, 14, 15) gets exactly one line, as a real
``panotopo`` process would print it: exit status 2, one stderr line starting
``panotopo: error:``, no traceback, no library warning.

One table per command; each row is (arguments, a word the line must contain).
"""

from __future__ import annotations

import json
import os
import resource
import struct
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import cv2
import networkx as nx
import numpy as np
import pytest

from engine.synth.writers import write_ros1_bag, write_video
from test_sources_data import ros1_image, write_messages_bag

ROOT = Path(__file__).resolve().parent.parent
W, H = 128, 64


def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG that announces width x height but holds no pixels (what a header check sees)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)))


def _npz(path: Path, n: int = 12, d: int = 16, meta=None, vectors=None, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, d)).astype(np.float32) if vectors is None else vectors
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    meta = {"descriptor": "effnet-vlad", "shift": True, "interval": 1.0} if meta is None else meta
    np.savez(path, stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
             shifts=np.zeros(n, np.int64), descriptors=v, meta=np.array(json.dumps(meta)))
    return path


def _zip_bomb(path: Path) -> Path:
    """A .npz whose zip directory says descriptors.npy unpacks to 40 GiB (a zip bomb as
    the loader sees it; the real data stays small so the test is cheap)."""
    _npz(path)
    arrays = dict(np.load(path))
    with zipfile.ZipFile(path, "w") as zf:
        for name, arr in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, arr)
        zf.getinfo("descriptors.npy").file_size = 40 * 2**30
    return path


def _graphml(path: Path, indices: list[int]) -> Path:
    g = nx.Graph(generator="panotopo 0.1.0", neighbor_node_num=1)
    for k, idx in enumerate(indices):
        g.add_node(f"n{k}", index=idx, frame=k, stamp=float(k), shift=0, label="")
    for k in range(len(indices) - 1):
        g.add_edge(f"n{k}", f"n{k + 1}", kind="sequential", similarity=0.9, status="auto")
    g.add_edge("n0", f"n{len(indices) - 1}", kind="loop", similarity=0.9, status="auto")
    nx.write_graphml(g, path)
    return path


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("bad")
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 255, (H, W, 3), dtype=np.uint8) for _ in range(12)]
    write_video(d / "v.avi", frames, 10.0)
    write_ros1_bag(d / "r.bag", frames[:4], [1.0, 2.0, 3.0, 4.0])
    write_messages_bag(d / "zero.bag", [("/cam", 1.0, ros1_image(np.zeros((0, 0, 3), np.uint8), 1.0))])
    (d / "tiny").mkdir()
    for k in range(3):
        cv2.imwrite(str(d / "tiny" / f"{k}.png"), np.zeros((1, 2, 3), np.uint8))
    (d / "huge").mkdir()
    _png_header_only(d / "huge" / "0.png", 30000, 15000)
    _png_header_only(d / "huge" / "1.png", 30000, 15000)
    (d / "vocab.pt").write_bytes(b"not used")
    _npz(d / "good.npz")
    _npz(d / "meta_list.npz", meta=["descriptor", "effnet-vlad"])
    _npz(d / "fw_text.npz", meta={"descriptor": "effnet-vlad", "shift": True, "frame_width": "wide"})
    nan = np.random.default_rng(2).normal(size=(12, 16)).astype(np.float32)
    nan[3] = np.nan
    _npz(d / "nan.npz", vectors=nan)
    _zip_bomb(d / "bomb.npz")
    _npz(d / "big.npz", n=25_000, d=64)
    (d / "far.csv").write_text("t,x,y\n" + "".join(f"{1000 + k},{k},0\n" for k in range(10)))
    (d / "one.csv").write_text("t,x,y\n0,0,0\n")
    (d / "ok.csv").write_text("t,x,y\n" + "".join(f"{k},{k},0\n" for k in range(12)))
    _graphml(d / "dup.graphml", [0, 1, 1, 3])
    _graphml(d / "neg.graphml", [0, -1, 2, 3])
    # Issue 43, item 18: files that were accepted with nonsense, exit 0.
    _npz_arrays(d / "complex.npz", descriptors=(rng.normal(size=(12, 16)) * (1 + 1j)).astype(np.complex64))
    _npz_arrays(d / "bool.npz", descriptors=rng.random((12, 16)) > 0.5)
    _npz_arrays(d / "dup_frames.npz", frames=np.array([0, 1, 2, 3, 4, 5, 5, 6, 7, 8, 9, 10], np.int64))
    _npz_arrays(d / "frames_half.npz", frames=np.arange(12) + 0.5)
    _npz_arrays(d / "backwards.npz", stamps=np.array([0, 1, 2, 3, 4, 5, 2.5, 7, 8, 9, 10, 11], np.float64))
    _npz_arrays(d / "colours_width.npz", colours=rng.random((12, 100)).astype(np.float16))
    zero = rng.normal(size=(12, 16)).astype(np.float32)
    zero[4] = 0
    _npz_arrays(d / "zero_row.npz", descriptors=zero)
    (d / "huge.csv").write_text("t,x,y\n" + "".join(f"{k},{k * 1e300},0\n" for k in range(12)))
    (d / "ns.csv").write_text("t,x,y\n" + "".join(f"{1.7e18 + k * 1e9},{k},0\n" for k in range(12)))
    nx.write_graphml(nx.Graph(generator="panotopo 0.1.0", neighbor_node_num=1), d / "empty.graphml")
    _graphml(d / "four.graphml", [0, 1, 2, 3])
    return d


def _npz_arrays(path: Path, n: int = 12, d: int = 16, **arrays) -> Path:
    """A descriptors file written as is (no normalising), ``arrays`` replacing or adding keys."""
    rng = np.random.default_rng(5)
    v = rng.normal(size=(n, d)).astype(np.float32)
    base = dict(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                shifts=np.zeros(n, np.int64), descriptors=v / np.linalg.norm(v, axis=1, keepdims=True),
                meta=np.array(json.dumps({"descriptor": "effnet-vlad", "shift": True, "interval": 1.0})))
    np.savez(path, **{**base, **arrays})
    return path


def run(data: Path, *args, limit_memory: bool = False) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), PANOTOPO_CACHE=str(data / "cache"))

    def limit():  # 6 GiB of address space: a map that does not fit fails fast instead of swapping
        resource.setrlimit(resource.RLIMIT_AS, (6 * 2**30, 6 * 2**30))
    return subprocess.run([sys.executable, "-m", "engine", *map(str, args)], cwd=data, env=env,
                          capture_output=True, text=True, timeout=300,
                          preexec_fn=limit if limit_memory else None)


def assert_one_line(proc: subprocess.CompletedProcess, word: str) -> None:
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, f"exit {proc.returncode}: {proc.stderr[-1500:]}"
    assert len(lines) == 1, proc.stderr[-1500:]
    assert lines[0].startswith("panotopo: error:"), lines[0]
    assert word.lower() in lines[0].lower(), lines[0]


MAP = [
    (["v.avi", "--interval", "nan"], "--interval"),
    (["v.avi", "--interval", "inf"], "--interval"),
    (["v.avi", "--interval", "1e-300"], "--interval"),
    (["v.avi", "--interval", "-1"], "--interval"),
    (["r.bag", "--interval", "1e-300"], "--interval"),
    (["r.bag", "--interval", "-1"], "--interval"),
    (["v.avi", "--neighbor-node-num", "1e9"], "--neighbor-node-num"),
    (["v.avi", "--neighbor-node-num", "1000000000"], "--neighbor-node-num"),
    (["v.avi", "--window-size", "0"], "--window-size"),
    (["v.avi", "--count-th", "-1"], "--count-th"),
    (["v.avi", "--input-height", "16000"], "--input-height"),
    (["v.avi", "--batch-size", "0"], "--batch-size"),
    (["v.avi", "--device", "bogus"], "--device"),
    (["v.avi", "--vocabulary", "vocab.pt"], "--vocabulary"),
    (["v.avi", "--node-sim-th", "nan"], "--node-sim-th"),
    (["v.avi", "--loop-sim-th", "nan"], "--loop-sim-th"),
    (["v.avi", "--loop-sim-th", "7"], "--loop-sim-th"),
    (["v.avi", "--method", "ours", "--loop-sim-th", "-3"], "--loop-sim-th"),
    (["tiny"], "too small"),
    (["huge"], "30000x15000"),
    (["zero.bag"], "zero.bag: frame 0"),
    (["meta_list.npz"], "meta"),
    (["fw_text.npz"], "frame_width"),
    (["nan.npz"], "not finite"),
    (["bomb.npz"], "GiB"),
    (["good.npz", "--poses", "far.csv"], "clock"),
    (["good.npz", "--poses", "one.csv"], "at least two"),
    (["complex.npz"], "complex numbers"),
    (["bool.npz"], "true/false"),
    (["dup_frames.npz"], "frame 5 is described twice"),
    (["backwards.npz"], "stamps run backwards at row 6"),
    (["frames_half.npz"], "whole numbers"),
    (["zero_row.npz"], "row 4 is all zeros"),
    (["good.npz", "--poses", "huge.csv"], "metres"),
    (["good.npz", "--poses", "ns.csv"], "seconds"),
    (["good.npz", "--plot", "out.graphml"], "the same file as --output"),
    (["good.npz", "--plot", "./out.graphml"], "the same file as --output"),
]


@pytest.mark.parametrize("args, word", MAP, ids=[" ".join(a) for a, _ in MAP])
def test_map(data, args, word):
    assert_one_line(run(data, "map", *args, "-o", "out.graphml", "--method", "shift-simple", "-q")
                    if "--method" not in args else run(data, "map", *args, "-o", "out.graphml", "-q"), word)


DESCRIBE = [
    (["v.avi", "--interval", "nan"], "--interval"),
    (["v.avi", "--device", "bogus"], "--device"),
    (["v.avi", "--input-height", "16000"], "--input-height"),
    (["v.avi", "--vocabulary", "vocab.pt"], "--vocabulary"),
    (["tiny"], "too small"),
    (["huge"], "30000x15000"),
    (["v.avi", "-o", "v.avi"], "same file"),
]


@pytest.mark.parametrize("args, word", DESCRIBE, ids=[" ".join(a) for a, _ in DESCRIBE])
def test_describe(data, args, word):
    out = [] if "-o" in args else ["-o", "out.npz"]
    assert_one_line(run(data, "describe", *args, *out, "-q"), word)


def test_describe_cuda_without_cuda(data):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    assert_one_line(run(data, "describe", "v.avi", "-o", "out.npz", "--device", "cuda", "-q"), "CUDA")


EVAL = [
    (["dup.graphml", "--poses", "ok.csv"], "same index"),
    (["neg.graphml", "--poses", "ok.csv"], "index -1"),
    (["good.npz", "--poses", "ok.csv"], "GraphML"),
    (["dup.graphml", "--poses", "ok.csv", "--dist-th", "nan"], "--dist-th"),
    (["dup.graphml", "--poses", "ok.csv", "--dist-th", "-1"], "--dist-th"),
    (["empty.graphml", "--poses", "ok.csv"], "no nodes"),
    (["four.graphml", "--poses", "huge.csv"], "metres"),
    (["four.graphml", "--poses", "ok.csv", "--plot", "four.graphml"], "same file"),
]


@pytest.mark.parametrize("args, word", EVAL, ids=[" ".join(a) for a, _ in EVAL])
def test_eval(data, args, word):
    assert_one_line(run(data, "eval", *args), word)


def test_colours_of_the_wrong_width_are_ignored_with_one_line(data):
    """No method reads colours now: a file with colours panotopo cannot have written maps
    without them, and says so (issue 43 item 18 asked for a line instead of silence)."""
    proc = run(data, "map", "colours_width.npz", "-o", "out_colours.graphml", "--method", "shift-simple", "-q")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "ignored its 'colours'" in lines[0], proc.stderr


def test_eval_poses_on_another_clock(data, tmp_path):
    graphml = _graphml(tmp_path / "m.graphml", [0, 1, 2, 3])
    assert_one_line(run(data, "eval", graphml, "--poses", "far.csv"), "clock")


DEMO = [
    (["--seed", "-1"], "--seed"),
    (["--interval", "nan"], "--interval"),
    (["--width", "10"], "--width"),
    (["--input-height", "16000"], "--input-height"),
]


@pytest.mark.parametrize("args, word", DEMO, ids=[" ".join(a) for a, _ in DEMO])
def test_demo(data, args, word, tmp_path):
    assert_one_line(run(data, "demo", "--out", tmp_path / "demo", *args, "-q"), word)
