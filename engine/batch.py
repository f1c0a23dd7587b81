"""Describe many recordings as one batch on Dask (``panotopo describe A B C --out-dir DIR``).

The contract:

* One task per recording, run on a Dask worker by ``describe_one``: the same
  ``engine.pipeline.describe`` as the single-process ``panotopo describe`` (same settings,
  no descriptor cache), so the arrays of the two .npz files are identical.
* Output names (``output_paths``): ``DIR/<input file name>.npz`` (``run1.mp4`` ->
  ``run1.mp4.npz``; a ROS2 bag folder or an image folder -> ``<folder name>.npz``). Inputs whose
  file names are equal (compared case-blind, for file systems that are) ALL get the first 8 hex
  digits of the SHA-1 of their absolute path before ``.npz`` (``a/run.mp4`` ->
  ``run.mp4-1f0c2a9b.npz``): the name depends on the path alone, not on the order of the inputs,
  so a rerun with the inputs in another order finds the same files. The same path given twice
  is described once.
* Each .npz is the recording's output and its checkpoint. It is written atomically
  (``engine.outputs.write_atomically``: a temporary file renamed into place), so a killed run
  never leaves a half file under the final name; the temporary file a killed writer left
  (``.<name>.npz.<random>.tmp``) is removed when the recording is described again. "Already done" (``is_done``) means: the file exists, loads, and its
  meta ``batch.key`` equals the key of this run for this recording (``done_key``: the recording's
  identity, absolute path, size and mtime, for a folder its files too; every describe setting:
  descriptor, interval, topic, shift, options, skip-bad-frames; the versions of the column,
  feature signatures). Anything else is described again, over the old file.
  A file written by the single-process ``describe`` carries no key, so a batch describes it again.
* A worker takes a Dask lock named after the output while it checks and describes, so two runs
  against one cluster (a client killed while its task runs on, and its rerun) never describe one
  recording at the same time; the second finds it done.
* One bad recording fails alone: ``describe_batch`` returns an ``Outcome`` per recording
  (status "described", "done" or "failed" with a one-line reason) and the CLI exits non-zero
  when any failed.
* Where: a local cluster by default (``local_cluster``: when the descriptor runs on a GPU
  (``uses_gpu``: its device "auto" or "cuda") and there are GPUs, one worker per GPU with
  ``CUDA_VISIBLE_DEVICES`` set to its own GPU and a ``GPU`` resource; else one single-threaded
  worker per core), or an existing scheduler (``scheduler="tcp://host:8786"``) whose workers see
  the same paths (docs/cluster.md). When the descriptor runs on a GPU and any worker of the
  cluster has a ``GPU`` resource, every task asks for one.
* Progress: workers send (recording, frames done, frames expected) as Dask events under a topic
  of this run; ``BatchBars`` draws two tqdm bars on stderr, recordings and frames.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

from .errors import InputError, OutputError, PanotopoError

# Key of the batch record in a .npz's meta (an addition to the .npz contract).
META_KEY = "batch"
# Seconds between two progress events of one recording (the last frame always goes).
PROGRESS_EVERY_S = 0.25
# How long a client waits for the first worker of an existing cluster.
WORKER_WAIT_S = 60.0
MAX_WORKERS = 4096


@dataclass(frozen=True)
class Job:
    """One recording of a batch: ``source`` as the user gave it, ``path`` absolute (what the
    workers open), ``output`` the absolute .npz path."""
    source: str
    path: str
    output: str


@dataclass
class Outcome:
    """What became of one recording: ``status`` "described" | "done" | "failed"."""
    job: Job
    status: str
    message: str = ""
    descriptors: int = 0
    seconds: float = 0.0
    worker: str = ""


@dataclass
class BatchResult:
    outcomes: list[Outcome] = field(default_factory=list)
    duplicates: list[str] = field(default_factory=list)   # inputs given more than once

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes if o.status == "failed"]


# ----------------------------------------------------------------------------- names and keys

def _absolute(path: str | Path) -> str:
    return os.path.normpath(os.path.abspath(os.fspath(path)))


def output_paths(inputs: Sequence[str | Path], out_dir: str | Path) -> tuple[list[Job], list[str]]:
    """The jobs of ``inputs`` (first occurrence of each absolute path, in the given order) and
    the inputs left out as repeats. Naming rules: module docstring."""
    out_dir = Path(_absolute(out_dir))
    seen: dict[str, str] = {}
    repeats: list[str] = []
    for given in inputs:
        path = _absolute(given)
        if path in seen:
            repeats.append(str(given))
            continue
        seen[path] = str(given)
    names = {path: Path(path).name or "recording" for path in seen}
    groups: dict[str, list[str]] = {}
    for path, name in names.items():
        groups.setdefault(name.casefold(), []).append(path)
    jobs: list[Job] = []
    taken: set[str] = set()
    for path, given in seen.items():
        name = names[path]
        if len(groups[name.casefold()]) > 1:
            name = f"{name}-{hashlib.sha1(path.encode('utf-8')).hexdigest()[:8]}"
        out = f"{name}.npz"
        if out.casefold() in taken:   # only by an input literally named like a disambiguated one
            raise InputError(f"{given}: its output name {out} is taken by another input; rename one of them")
        taken.add(out.casefold())
        jobs.append(Job(source=given, path=path, output=str(out_dir / out)))
    return jobs, repeats


def _plain_settings(settings) -> dict:
    """``DescribeSettings`` as plain JSON data (what travels to workers and into the key)."""
    data = settings.as_dict() if hasattr(settings, "as_dict") else dict(settings)
    return json.loads(json.dumps(data, sort_keys=True, default=str))


def done_key(path: str | Path, settings) -> Optional[str]:
    """The key a finished .npz of recording ``path`` under ``settings`` carries; None when
    ``path`` cannot be read here (then only a worker can tell)."""
    from .descriptors.cache import cache_key
    from .features import FEATURES_VERSION
    from .verify import COLUMNS_VERSION

    plain = _plain_settings(settings)
    try:
        return cache_key(path, {"interval": plain.get("interval"), "topic": plain.get("topic")},
                         {"describe": plain, "columns": COLUMNS_VERSION,
                          "features": FEATURES_VERSION})
    except OSError:
        return None


def _stored_key(output: Path, full: bool) -> Optional[str]:
    """``batch.key`` of the .npz at ``output``; None when it is missing or does not load.
    ``full`` loads every array (``Descriptors.load``, with its checks); otherwise only the
    zip directory and the meta are read (the client's quick look before submitting)."""
    import numpy as np

    if not output.is_file():
        return None
    try:
        if full:
            from .descriptors.base import Descriptors

            meta = Descriptors.load(output).meta
        else:
            with np.load(output, allow_pickle=False) as z:
                if not {"stamps", "frames", "shifts", "descriptors", "meta"} <= set(z.files):
                    return None
                meta = json.loads(str(z["meta"]))
    except Exception:   # unreadable, truncated, not ours: not done, describe it again
        return None
    record = meta.get(META_KEY) if isinstance(meta, dict) else None
    return record.get("key") if isinstance(record, dict) else None


def is_done(output: str | Path, key: Optional[str], full: bool = True) -> bool:
    """Whether ``output`` is a finished .npz for ``key`` (see ``done_key``)."""
    return key is not None and _stored_key(Path(output), full) == key


# ----------------------------------------------------------------------------- on a worker

class _EventProgress:
    """A ``Progress`` callback that sends (output, done, total) as Dask events, throttled."""

    def __init__(self, worker, topic: Optional[str], output: str):
        self.worker, self.topic, self.output = worker, topic, output
        self.last = 0.0

    def __call__(self, done: int, total: int, stage: str) -> None:
        if self.worker is None or not self.topic:
            return
        now = time.monotonic()
        if now - self.last < PROGRESS_EVERY_S and not (total and done >= total):
            return
        self.last = now
        self.send(int(done), int(total))

    def send(self, done: int, total: int) -> None:
        if self.worker is None or not self.topic:
            return
        try:
            self.worker.log_event(self.topic, {"output": self.output, "done": done, "total": total})
        except Exception:   # progress is a courtesy; it never fails a recording
            pass


_MALLOC_SET = False
# glibc mallopt parameters (malloc.h) and the values set on a Dask worker.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 << 20
TRIM_THRESHOLD_BYTES = 128 << 20


def _malloc_for_arrays() -> None:
    """Undo, in this worker process, what Dask's nanny's MALLOC_TRIM_THRESHOLD_=65536 does to
    describing: glibc then keeps its mmap threshold at 128 KiB, so every frame-sized array is a
    fresh mmap, page-faulted and unmapped again. Measured (2-core machine, 4 recordings of 24
    frames 512x256, effnet-vlad, one torch thread): 12.3 s wall / 2.8 s system time with it,
    3.6 s / 0.1 s after mallopt(M_MMAP_THRESHOLD, 32 MiB) + mallopt(M_TRIM_THRESHOLD, 128 MiB),
    4.0 s / 0.4 s without the variable. Once per process, glibc on Linux only, best effort."""
    global _MALLOC_SET
    if _MALLOC_SET or "MALLOC_TRIM_THRESHOLD_" not in os.environ or not sys.platform.startswith("linux"):
        return
    _MALLOC_SET = True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
    except (OSError, AttributeError):
        pass


def _current_worker():
    try:
        from distributed import get_worker

        return get_worker()
    except (ImportError, ValueError):
        return None


def _remove_leftovers(output: Path) -> None:
    """Remove the temporary files a killed writer of ``output`` left (``write_atomically``'s
    ``.<name>.<random>.tmp``); called under the output's lock, so no live writer owns them."""
    for stale in output.parent.glob(f".{output.name}.*.tmp"):
        try:
            stale.unlink()
        except OSError:
            pass


def describe_one(path: str, output: str, settings: dict, topic: Optional[str] = None,
                 run: str = "") -> dict:
    """Describe the recording at ``path`` into ``output`` unless it is already done; the
    task every worker runs (also callable in-process). Returns {"status": "described" |
    "done", "descriptors": n, "seconds": s, "worker": address}. Bad input raises
    ``InputError`` (one line); the client reports it and goes on with the others."""
    from contextlib import nullcontext

    from .pipeline import DescribeSettings, describe, is_descriptor_file

    worker = _current_worker()
    address = getattr(worker, "address", "") if worker is not None else ""
    if worker is not None:
        _malloc_for_arrays()
    if is_descriptor_file(path):
        raise InputError(f"{path}: already a descriptors file (.npz); nothing to describe")
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file or directory" + (f" on worker {address}" if address else ""))
    guard = nullcontext()
    if worker is not None:
        from distributed import Lock

        guard = Lock(f"panotopo-describe:{output}")
    described = DescribeSettings(**settings)
    with guard:
        key = done_key(path, described)
        if is_done(output, key, full=True):
            return {"status": "done", "descriptors": 0, "seconds": 0.0, "worker": address}
        _remove_leftovers(Path(output))
        progress = _EventProgress(worker, topic, output)
        start = time.perf_counter()
        descs = describe(path, described, progress=progress, cache=None)
        seconds = time.perf_counter() - start
        descs.meta[META_KEY] = {"key": key, "run": run, "worker": address, "seconds": round(seconds, 3)}
        descs.save(output)
        progress.send(len(descs), len(descs))
    return {"status": "described", "descriptors": len(descs), "seconds": seconds, "worker": address,
            "skipped": list(descs.meta.get("skipped_frames") or [])}


# ----------------------------------------------------------------------------- clusters

def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def gpu_count() -> int:
    """CUDA devices this machine's torch sees (0 without CUDA)."""
    try:
        import torch

        return int(torch.cuda.device_count()) if torch.cuda.is_available() else 0
    except Exception:
        return 0


def uses_gpu(settings) -> bool:
    """Whether ``settings`` run the descriptor's network on a GPU where there is one: its
    ``device`` option (given, or the model's default: effnet-vlad's is "cpu", the others'
    "auto") is "auto" or names CUDA."""
    import inspect

    from . import descriptors as registry

    plain = _plain_settings(settings)
    device = (plain.get("options") or {}).get("device")
    if device is None:
        try:
            parameter = inspect.signature(registry.model_class(plain["descriptor"])).parameters.get("device")
        except (InputError, KeyError):
            return False
        device = None if parameter is None else parameter.default
    return isinstance(device, str) and (device == "auto" or device.startswith("cuda"))


def _visible_devices(gpus: int) -> list[str]:
    """The CUDA_VISIBLE_DEVICES entry of each of ``gpus`` devices (a restriction the user set
    on this process is kept: worker i gets the i-th device of it)."""
    given = [d.strip() for d in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",") if d.strip()]
    return given[:gpus] if len(given) >= gpus else [str(i) for i in range(gpus)]


def local_cluster(workers: Optional[int] = None, gpus: Optional[int] = None):
    """A Dask cluster on this machine (127.0.0.1 only, no dashboard, no memory limit per worker:
    ``describe`` checks memory itself).

    With GPUs: ``workers`` (default one per GPU) single-threaded workers, worker i sees only GPU
    i mod the GPU count (``CUDA_VISIBLE_DEVICES``), has resource ``GPU=1`` and the CPU cores
    shared out for decoding. Without: ``workers`` (default one per core) single-threaded workers
    with one torch thread each (Dask's default OMP_NUM_THREADS=1). The workers' own log lines
    (a failed task's traceback) are silenced: each failure is reported once, in one line."""
    from distributed import LocalCluster, Nanny, Scheduler, SpecCluster

    gpus = gpu_count() if gpus is None else gpus
    if gpus:
        n = workers or gpus
        devices = _visible_devices(gpus)
        threads = str(max(1, _cores() // n))
        spec = {f"gpu-{i}": {"cls": Nanny, "options": {
            "nthreads": 1, "memory_limit": 0, "host": "127.0.0.1", "resources": {"GPU": 1},
            "env": {"CUDA_VISIBLE_DEVICES": devices[i % gpus], "OMP_NUM_THREADS": threads,
                    "MKL_NUM_THREADS": threads}}} for i in range(n)}
        scheduler = {"cls": Scheduler, "options": {"host": "127.0.0.1", "dashboard_address": None}}
        return SpecCluster(workers=spec, scheduler=scheduler, silence_logs=logging.CRITICAL)
    return LocalCluster(n_workers=workers or _cores(), threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address=None, memory_limit=0,
                        silence_logs=logging.CRITICAL)


def _connect(scheduler: Optional[str], workers: Optional[int], gpu: bool):
    """(client, cluster or None): a client of ``scheduler`` or of a new local cluster (with GPU
    workers only when ``gpu``: the descriptor runs on one)."""
    from distributed import Client

    if scheduler is None:
        cluster = local_cluster(workers, gpus=None if gpu else 0)
        return Client(cluster), cluster
    try:
        client = Client(scheduler, timeout="15s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there "
                         f"({exc.__class__.__name__})") from None
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except (TimeoutError, OSError):
        client.close()
        raise InputError(f"--scheduler {scheduler}: no worker joined within {WORKER_WAIT_S:g} s") from None
    return client, None


def _wants_gpu(client) -> bool:
    workers = client.scheduler_info().get("workers", {})
    return any("GPU" in (w.get("resources") or {}) for w in workers.values())


# ----------------------------------------------------------------------------- the batch

def _reason(exc: BaseException) -> str:
    """One line for a failed recording."""
    if isinstance(exc, PanotopoError):
        text = str(exc)
    elif exc.__class__.__name__ == "KilledWorker":
        text = "the worker describing it died (out of memory? see the worker's log)"
    elif isinstance(exc, MemoryError):
        text = "not enough memory on the worker"
    else:
        text = f"{exc.__class__.__name__}: {exc}"
    return " ".join(text.split())


BatchProgress = Callable[[int, int, int, int], None]   # (recordings done, of, frames done, of)


class _Tally:
    """Frames done / expected per recording, fed by worker events (another thread)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.frames: dict[str, tuple[int, int]] = {}

    def event(self, event) -> None:
        msg = event[1] if isinstance(event, (tuple, list)) and len(event) == 2 else event
        try:
            out, done, total = msg["output"], int(msg["done"]), int(msg["total"])
        except (TypeError, KeyError, ValueError):
            return
        with self.lock:
            self.frames[out] = (done, max(total, done))

    def finish(self, output: str, n: int) -> None:
        with self.lock:
            done, total = self.frames.get(output, (0, 0))
            self.frames[output] = (max(done, n), max(total, n))

    def sums(self) -> tuple[int, int]:
        with self.lock:
            return sum(d for d, _ in self.frames.values()), sum(t for _, t in self.frames.values())


def describe_batch(inputs: Sequence[str | Path], out_dir: str | Path, settings,
                   scheduler: Optional[str] = None, workers: Optional[int] = None,
                   progress: Optional[BatchProgress] = None,
                   said: Optional[Callable[[Outcome], None]] = None) -> BatchResult:
    """Describe every recording of ``inputs`` into ``out_dir`` (see the module docstring).

    ``settings``: ``DescribeSettings`` (as the single-process describe gets them). ``said`` is
    called with each outcome as it happens (done, described or failed). Raises InputError only
    for what stops the whole batch (the output folder, the scheduler); a recording's own
    problem is its failed ``Outcome``."""
    from . import descriptors as registry

    plain = _plain_settings(settings)
    if plain.get("descriptor") not in registry.REGISTRY:
        registry.model_class(plain.get("descriptor"))   # InputError: one line naming the choices
    out = Path(_absolute(out_dir))
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out_dir}: --out-dir must be a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{out_dir}: cannot create the output folder ({exc.strerror})") from None
    jobs, repeats = output_paths(inputs, out)
    result = BatchResult(duplicates=repeats)
    tell = said or (lambda outcome: None)
    report = progress or (lambda *a: None)

    todo: list[Job] = []
    for job in jobs:
        if is_done(job.output, done_key(job.path, settings), full=False):
            outcome = Outcome(job, "done")
            result.outcomes.append(outcome)
            tell(outcome)
        else:
            todo.append(job)
    report(len(result.outcomes), len(jobs), 0, 0)
    if not todo:
        return result

    run = uuid.uuid4().hex[:12]
    topic = f"panotopo-progress-{run}"
    tally = _Tally()
    gpu = uses_gpu(settings)
    client, cluster = _connect(scheduler, workers, gpu)
    futures = {}
    try:
        client.subscribe_topic(topic, tally.event)
        resources = {"GPU": 1} if gpu and _wants_gpu(client) else None
        for i, job in enumerate(todo):
            digest = hashlib.sha1(job.output.encode("utf-8")).hexdigest()[:12]
            future = client.submit(describe_one, job.path, job.output, plain, topic, run,
                                   key=f"panotopo-describe-{digest}-{run}", resources=resources,
                                   priority=len(todo) - i, pure=False)
            futures[future] = job
        pending = set(futures)
        while pending:
            finished = [f for f in pending if f.done()]
            for f in finished:
                pending.discard(f)
                job = futures[f]
                if f.status == "finished":
                    value = f.result()
                    outcome = Outcome(job, value["status"], descriptors=value["descriptors"],
                                      seconds=value["seconds"], worker=value["worker"])
                    if value.get("skipped"):
                        outcome.message = (f"skipped {len(value['skipped'])} undecodable frame(s) "
                                           f"(first: {value['skipped'][0]})")
                    tally.finish(job.output, value["descriptors"])
                else:
                    exc = f.exception() if f.status == "error" else None
                    outcome = Outcome(job, "failed", message=_reason(exc) if exc else f"task {f.status}")
                result.outcomes.append(outcome)
                tell(outcome)
            report(len(result.outcomes), len(jobs), *tally.sums())
            if pending:
                time.sleep(0.1)
    finally:
        for f in futures:
            if not f.done():
                f.cancel()
        try:
            client.unsubscribe_topic(topic)
        except Exception:
            pass
        client.close()
        if cluster is not None:
            cluster.close()
    order = {job.output: i for i, job in enumerate(jobs)}
    result.outcomes.sort(key=lambda o: order[o.job.output])
    return result


# ----------------------------------------------------------------------------- the command

class BatchBars:
    """Two tqdm bars on stderr, recordings and frames, for ``describe_batch(progress=...)``."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.bars = None

    def __call__(self, done: int, total: int, frames: int, frames_total: int) -> None:
        if self.quiet:
            return
        import sys

        from tqdm import tqdm

        if self.bars is None:
            self.bars = (tqdm(total=total, desc="recordings", unit="rec", file=sys.stderr, position=0,
                              mininterval=0.5),
                         tqdm(total=None, desc="frames", unit="frame", file=sys.stderr, position=1,
                              mininterval=0.5))
        recs, frame_bar = self.bars
        if frames_total and frame_bar.total != frames_total:
            frame_bar.total = frames_total
        if frames > frame_bar.n:
            frame_bar.update(frames - frame_bar.n)   # tqdm redraws at most every mininterval
        if done > recs.n:
            recs.update(done - recs.n)

    def writing(self):
        """A context in which printing leaves the bars whole (cleared, then redrawn)."""
        from contextlib import nullcontext

        if self.bars is None:
            return nullcontext()
        from tqdm import tqdm

        return tqdm.external_write_mode()

    def close(self) -> None:
        if self.bars is not None:
            for bar in self.bars:
                bar.close()
            self.bars = None


def check_form(args) -> None:
    """The describe command's two forms: ``INPUT -o OUT.npz`` (single process, unchanged) or
    ``INPUT... --out-dir DIR [--scheduler ADDRESS] [--workers N]`` (a batch); InputError
    otherwise. Sets ``args.input`` to the one input of the single form (None for a batch)."""
    inputs = list(args.inputs)
    args.input = None
    if args.out_dir is None:
        if args.scheduler is not None or args.workers is not None:
            raise InputError("--scheduler and --workers go with --out-dir DIR (a batch)")
        if len(inputs) != 1:
            raise InputError(f"describe of {len(inputs)} recordings writes one .npz each: give --out-dir DIR "
                             f"instead of -o")
        if args.output is None:
            raise InputError("describe needs -o OUT.npz (one recording) or --out-dir DIR (a batch)")
        args.input = inputs[0]
        return
    if args.output is not None:
        raise InputError("give either -o OUT.npz (one recording) or --out-dir DIR (a batch), not both")
    if args.workers is not None:
        if args.scheduler is not None:
            raise InputError("--workers sizes the local cluster; an existing cluster (--scheduler) has its own")
        if not 1 <= args.workers <= MAX_WORKERS:
            raise InputError(f"--workers must be between 1 and {MAX_WORKERS}, got {args.workers}")


def run_command(args, settings, say: Callable[[str], None], warn: Callable[[str], None]) -> int:
    """``panotopo describe INPUT... --out-dir DIR``: 0 when every recording is done, 2 when any
    failed (each named on stderr in one line, after the others finished)."""
    bars = BatchBars(args.quiet)

    def said(o: Outcome) -> None:
        with bars.writing():
            _tell(o)

    def _tell(o: Outcome) -> None:
        if o.status == "described":
            say(f"wrote {o.job.output}: {o.descriptors} descriptors of {o.job.source} "
                f"({o.seconds:.1f} s{', ' + o.worker if o.worker else ''})")
            if o.message:
                warn(f"{o.job.source}: {o.message}")
        elif o.status == "done":
            say(f"already done: {o.job.output} ({o.job.source})")

    try:
        result = describe_batch(args.inputs, args.out_dir, settings, scheduler=args.scheduler,
                                workers=args.workers, progress=bars, said=said)
    finally:
        bars.close()
    for given in result.duplicates:
        warn(f"{given} was given more than once; described once")
    for o in result.failed:
        named = o.message.startswith((o.job.source, o.job.path))
        warn(f"error: {o.message}" if named else f"error: {o.job.source}: {o.message}")
    say(f"{len(result.outcomes)} recordings: {result.count('described')} described, "
        f"{result.count('done')} already done, {len(result.failed)} failed")
    return 2 if result.failed else 0
