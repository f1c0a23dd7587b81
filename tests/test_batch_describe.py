"""``panotopo describe A B C --out-dir DIR``: a batch on Dask (engine/batch.py).

Properties tested with real parts (videos written with PyAV, the CLI as a subprocess, a local
cluster of 2 workers, a real ``dask scheduler`` + ``dask worker`` on 127.0.0.1):

* killed as soon as some .npz exist and run again, the batch finishes the rest: the finished
  files are untouched (inode, mtime, run id), the rerun describes exactly the missing ones,
  each once, and says the others are done;
* the batch's arrays equal those of the single-process ``describe INPUT -o OUT.npz``;
* "done" means the same recording and settings: other settings or a truncated file are not done;
* against an existing scheduler the batch works; bad recordings among good ones are each
  reported in one line on stderr (no traceback), the others finish, the exit status is 2;
* output names: DIR/<file name>.npz, equal names disambiguated by their path's hash whatever
  the order, a path given twice described once; wrong forms of the command: one line, exit 2.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from engine.batch import META_KEY, done_key, is_done, output_paths
from engine.cli import _describe_command_settings, build_parser, main

ROOT = Path(__file__).resolve().parent.parent
N_RECORDINGS = 8
FRAMES, FPS, W, H = 10, 4, 256, 128
INTERVAL = "0.25"   # every frame
ARRAYS = ("stamps", "frames", "shifts", "descriptors", "columns", "colours")


def write_recording(path: Path, seed: int) -> Path:
    """A short 2:1 video of a random blocky panorama turning a little each frame."""
    from benchmarks.bench_batch import write_recording as write

    return write(path, seed, FRAMES, W, FPS)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("recordings")
    return [write_recording(d / f"rec{k}.mp4", seed=k) for k in range(N_RECORDINGS)]


def batch_command(inputs, out_dir, *extra) -> list[str]:
    return [sys.executable, "-m", "engine", "describe", *map(str, inputs), "--out-dir", str(out_dir),
            "--interval", INTERVAL, *extra]


def finished(out_dir: Path) -> dict[str, tuple[int, int]]:
    """{file name: (inode, mtime_ns)} of the finished .npz (temporary files start with '.')."""
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in out_dir.glob("*.npz")
            if not p.name.startswith(".")}


def run_id(path: Path) -> str:
    with np.load(path, allow_pickle=False) as z:
        return json.loads(str(z["meta"]))[META_KEY]["run"]


def kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


@pytest.fixture(scope="module")
def resumed(recordings, tmp_path_factory) -> dict:
    """A batch on a local cluster of 2 workers killed (SIGKILL to the command) once some .npz
    exist, then run again to the end."""
    out = tmp_path_factory.mktemp("batch") / "out"
    cmd = batch_command(recordings, out, "--workers", "2")
    first = subprocess.Popen(cmd + ["-q"], cwd=ROOT, start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 300
        while not (out.is_dir() and finished(out)):
            assert first.poll() is None, f"the batch ended before any .npz: {first.stderr.read().decode()}"
            assert time.monotonic() < deadline, "no .npz within 300 s"
            time.sleep(0.05)
        os.kill(first.pid, signal.SIGKILL)   # the command only; its workers must go with it
        first.wait(timeout=30)
        time.sleep(1.0)
    finally:
        kill_group(first)                      # whatever was left of the first run
    before = finished(out)
    for rec in recordings:   # what a writer killed in the middle of its rename would leave
        (out / f".{rec.name}.npz.k1ll3d.tmp").write_bytes(b"half")
    second = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    return {"out": out, "before": before, "second": second, "recordings": recordings}


def test_a_killed_batch_finishes_the_rest_without_describing_anything_twice(resumed):
    out, before, second = resumed["out"], resumed["before"], resumed["second"]
    names = {f"{p.name}.npz" for p in resumed["recordings"]}
    assert 0 < len(before) < len(names), f"the kill did not land halfway: {sorted(before)}"
    assert second.returncode == 0, second.stderr
    after = finished(out)
    assert set(after) == names
    assert all(after[n] == before[n] for n in before)   # finished files untouched: inode and mtime
    lines = second.stdout.splitlines()
    described = [Path(line.split()[1].rstrip(":")).name for line in lines if line.startswith("wrote ")]
    done = [Path(line.split()[2]).name for line in lines if line.startswith("already done: ")]
    assert sorted(described) == sorted(names - set(before))   # each missing one once, nothing twice
    assert sorted(done) == sorted(before)
    leftovers = {p.name for p in out.glob(".*.tmp")}
    assert leftovers == {f".{n}.k1ll3d.tmp" for n in before}   # removed where described again
    first_runs = {run_id(out / n) for n in before}
    second_runs = {run_id(out / n) for n in names - set(before)}
    assert len(first_runs) == 1 and len(second_runs) == 1 and first_runs != second_runs
    assert "Traceback" not in second.stderr


def test_batch_arrays_equal_the_single_process_describe(resumed, tmp_path):
    out = resumed["out"]
    for rec in resumed["recordings"][:2]:
        single = tmp_path / f"{rec.name}.single.npz"
        assert main(["describe", str(rec), "-o", str(single), "--interval", INTERVAL, "--no-cache", "-q"]) == 0
        with np.load(single) as a, np.load(out / f"{rec.name}.npz") as b:
            assert set(a.files) == set(b.files)
            for name in a.files:
                if name != "meta":
                    assert a[name].dtype == b[name].dtype and np.array_equal(a[name], b[name]), name
            assert len(a["stamps"]) > 0


def test_done_means_same_recording_and_settings(resumed, tmp_path):
    rec, out = resumed["recordings"][0], resumed["out"]
    npz = out / f"{rec.name}.npz"

    def settings(*extra):
        return _describe_command_settings(build_parser().parse_args(["describe", str(rec), *extra]))

    assert is_done(npz, done_key(rec, settings("--interval", INTERVAL)))
    assert not is_done(npz, done_key(rec, settings("--interval", "0.5")))
    assert not is_done(npz, done_key(rec, settings("--interval", INTERVAL, "--no-shift")))
    assert not is_done(npz, done_key(resumed["recordings"][1], settings("--interval", INTERVAL)))
    cut = tmp_path / "cut.npz"
    cut.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    assert not is_done(cut, done_key(rec, settings("--interval", INTERVAL)))
    single = tmp_path / "single.npz"   # no batch key: a batch describes it again
    assert main(["describe", str(rec), "-o", str(single), "--interval", INTERVAL, "--no-cache", "-q"]) == 0
    assert not is_done(single, done_key(rec, settings("--interval", INTERVAL)))


@pytest.fixture
def dask_cluster(tmp_path):
    """``dask scheduler`` + ``dask worker --nworkers 2 --nthreads 1`` on 127.0.0.1, random ports."""
    info = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", str(info)],
            cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        deadline = time.monotonic() + 120
        while not (info.is_file() and info.stat().st_size > 0):
            assert time.monotonic() < deadline and procs[0].poll() is None, "the scheduler did not start"
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "dask", "worker", address, "--nworkers", "2", "--nthreads", "1",
             "--host", "127.0.0.1", "--no-dashboard"],
            cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        yield address
    finally:
        for proc in reversed(procs):
            kill_group(proc)


def test_an_existing_cluster_and_bad_recordings(recordings, dask_cluster, tmp_path):
    out = tmp_path / "out"
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(os.urandom(4000))
    missing = tmp_path / "missing.mp4"
    good = recordings[:4]   # as many as the cluster has workers, twice: enough to share out
    inputs = [*good[:2], broken, *good[2:], missing]
    res = subprocess.run(batch_command(inputs, out, "--scheduler", dask_cluster, "-q"), cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 2
    errors = [line for line in res.stderr.splitlines() if "error" in line]
    assert len(errors) == 2 and "Traceback" not in res.stderr, res.stderr
    assert any(str(broken) in line for line in errors) and any(str(missing) in line for line in errors)
    assert set(finished(out)) == {f"{p.name}.npz" for p in good}
    for rec in good:
        with np.load(out / f"{rec.name}.npz") as z:
            assert len(z["stamps"]) > 0 and json.loads(str(z["meta"]))[META_KEY]["worker"].startswith("tcp://")


def test_output_names(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    inputs = [a / "run.mp4", b / "run.mp4", a / "other.bag", b / "RUN.mp4", a / "run.mp4"]
    jobs, repeats = output_paths(inputs, tmp_path / "out")
    names = [Path(j.output).name for j in jobs]
    assert repeats == [str(a / "run.mp4")] and len(jobs) == 4
    assert names[2] == "other.bag.npz" and len({n.casefold() for n in names}) == 4
    assert all(n.startswith(("run.mp4-", "RUN.mp4-")) and n.endswith(".npz") for n in names[:2] + names[3:])
    again, _ = output_paths(list(reversed(inputs)), tmp_path / "out")   # the order changes nothing
    assert {j.path: j.output for j in again} == {j.path: j.output for j in jobs}
    assert all(Path(j.output).parent == tmp_path / "out" for j in jobs)


@pytest.mark.parametrize("args", [
    ["x.mp4", "y.mp4"],                                   # several, no --out-dir
    ["x.mp4", "y.mp4", "-o", "a.npz"],
    ["x.mp4", "-o", "a.npz", "--out-dir", "d"],
    ["x.mp4"],                                            # neither -o nor --out-dir
    ["x.mp4", "-o", "a.npz", "--workers", "2"],
    ["x.mp4", "--out-dir", "d", "--workers", "0"],
    ["x.mp4", "--out-dir", "d", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
    ["x.mp4", "y.mp4", "--out-dir", "d", "--descriptor", "nope"],   # refused before any cluster
])
def test_wrong_forms_get_one_line(args, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["describe", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("panotopo: error:")
    assert not (tmp_path / "d").exists()


def _env_of_worker() -> str:
    return os.environ.get("CUDA_VISIBLE_DEVICES", "")


def test_local_gpu_workers_each_see_their_own_gpu(monkeypatch):
    """The plumbing of one GPU per worker (no GPU needed): worker i has CUDA_VISIBLE_DEVICES set
    to the i-th device this process may use, and a GPU resource that the batch's tasks ask for."""
    from distributed import Client

    from engine.batch import _visible_devices, _wants_gpu, local_cluster, uses_gpu
    from engine.pipeline import DescribeSettings

    assert not uses_gpu(DescribeSettings())        # effnet-vlad runs on the CPU unless told
    assert uses_gpu(DescribeSettings(options={"device": "cuda"})) and uses_gpu(DescribeSettings(descriptor="megaloc"))
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "3,5")
    assert _visible_devices(2) == ["3", "5"]
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    assert _visible_devices(2) == ["0", "1"]
    with local_cluster(workers=2, gpus=2) as cluster, Client(cluster) as client:
        client.wait_for_workers(2, timeout=120)
        assert _wants_gpu(client)
        info = client.scheduler_info()["workers"]
        assert all(w["resources"] == {"GPU": 1} and w["nthreads"] == 1 for w in info.values())
        assert all(w.startswith("tcp://127.0.0.1:") for w in info)
        seen = client.run(_env_of_worker)
        assert sorted(seen.values()) == ["0", "1"]
