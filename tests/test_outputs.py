"""Outputs never replace an input or a non-regular file, temp files are unpredictable and
follow no links, modes follow the umask, messages name the user's file (issue 16,
findings 6, 7, 9, 15)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.graph import TopoMap
from engine.outputs import write_atomically, write_text
from engine.session import Session

ROOT = Path(__file__).resolve().parent.parent


def _descs(n: int = 12) -> Descriptors:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(n, 16)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                       shifts=np.zeros(n, np.int64), vectors=v,
                       meta={"descriptor": "effnet-vlad", "shift": True, "interval": 1.0})


def _map() -> TopoMap:
    g = nx.Graph(generator="panotopo test")
    for k in range(3):
        g.add_node(f"n{k}", index=k, frame=k, stamp=float(k), shift=0, label="")
    return TopoMap(g, dict(g.graph))


def _cli(*args, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), PANOTOPO_CACHE=str(cwd / "cache"))
    return subprocess.run([sys.executable, "-m", "engine", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def _one_error_line(proc) -> str:
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("panotopo: error:"), proc.stderr[-2000:]
    return lines[0]


def test_map_refuses_to_overwrite_its_input(tmp_path):
    npz = tmp_path / "x.npz"
    _descs().save(npz)
    before = npz.read_bytes()
    line = _one_error_line(_cli("map", npz, "-o", npz, "--method", "simple", cwd=tmp_path))
    assert "same file as the input" in line
    assert npz.read_bytes() == before


def test_describe_refuses_an_output_that_is_the_input_through_a_link(tmp_path):
    video = tmp_path / "in.avi"
    video.write_bytes(b"not really a video, but the user's file")
    (tmp_path / "alias.avi").symlink_to(video)
    line = _one_error_line(_cli("describe", video, "-o", tmp_path / "alias.avi", cwd=tmp_path))
    assert "same file as the input" in line
    assert video.read_bytes().startswith(b"not really")


@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_a_non_regular_output_is_refused_not_replaced(tmp_path, kind):
    target = tmp_path / "out.graphml"
    if kind == "fifo":
        os.mkfifo(target)
    else:
        target.mkdir()
    with pytest.raises(InputError, match="out.graphml"):
        _map().write_graphml(target)
    assert stat.S_ISFIFO(target.lstat().st_mode) if kind == "fifo" else target.is_dir()


def test_dev_full_is_refused_before_writing():
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    with pytest.raises(InputError, match="not a regular file"):
        write_text("/dev/full", "x")
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_a_symlink_is_written_through(tmp_path):
    real = tmp_path / "maps" / "real.graphml"
    real.parent.mkdir()
    real.write_text("old")
    link = tmp_path / "latest.graphml"
    link.symlink_to(real)
    _map().write_graphml(link)
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert TopoMap.read_graphml(real).node_count == 3


def test_the_old_predictable_temp_name_is_not_followed(tmp_path):
    """Finding 7: ``<out>.tmp.npz`` was predictable and followed symlinks."""
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    out = tmp_path / "d.npz"
    (tmp_path / "d.npz.tmp.npz").symlink_to(victim)
    _descs().save(out)
    assert victim.read_text() == "keep me"
    assert len(Descriptors.load(out)) == 12
    leftovers = [p.name for p in tmp_path.iterdir() if p.name not in ("victim.txt", "d.npz", "d.npz.tmp.npz")]
    assert leftovers == []


@pytest.mark.parametrize("umask, mode", [(0o002, 0o664), (0o022, 0o644), (0o077, 0o600)])
def test_new_files_follow_the_umask(tmp_path, umask, mode):
    """Finding 9: sessions and maps were always 0600."""
    old = os.umask(umask)
    try:
        _map().write_graphml(tmp_path / "m.graphml")
        Session(input_path=str(tmp_path / "r.mp4")).save(tmp_path / "s.panotopo.json")
        _descs().save(tmp_path / "d.npz")
    finally:
        os.umask(old)
    for name in ("m.graphml", "s.panotopo.json", "d.npz"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


def test_an_existing_file_keeps_its_mode(tmp_path):
    path = tmp_path / "s.panotopo.json"
    path.write_text("{}")
    os.chmod(path, 0o664)
    old = os.umask(0o077)
    try:
        Session(input_path=str(tmp_path / "r.mp4")).save(path)
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o664


def test_errors_name_the_users_file_not_the_temp_file(tmp_path):
    def fail(f):
        raise OSError(28, "No space left on device")

    with pytest.raises(InputError) as err:
        write_atomically(tmp_path / "x.graphml", fail)
    assert "x.graphml" in str(err.value) and ".tmp" not in str(err.value)
    assert list(tmp_path.iterdir()) == []
