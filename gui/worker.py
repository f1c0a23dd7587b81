"""The pipeline run off the UI thread, on the app's one background mechanism
(``gui.background.Worker``): a run job, its result, and a controller that relays it."""

from __future__ import annotations

import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

from PySide6.QtCore import QObject, Signal

from engine.errors import Cancelled, InputError
from engine.params import MapParams

from .background import Job, Worker


@dataclass
class RunJob:
    path: Union[Path, list]       # a recording, or a site's inputs (``engine.site.map_site``)
    settings: object              # engine.pipeline.DescribeSettings
    params: MapParams
    cache: object = None          # engine.descriptors.cache.DescriptorCache


@dataclass
class FinishedRun:
    """What a finished job gives the window (``engine.run.RunResult`` narrowed to what it shows)."""

    job: RunJob
    descs: object                 # Descriptors
    topomap: object               # TopoMap
    seconds: float
    row_starts: list = field(default_factory=list)   # a site: first descriptor row of each recording
    sessions: list = field(default_factory=list)     # a site: the recordings' names, in map order
    notes: list = field(default_factory=list)        # a site: one line each for the user


def run_job(job: RunJob, work: Job) -> FinishedRun:
    """The pipeline run itself (on the worker thread): ``engine.run.run`` with the job's
    cancel event and progress reporter."""
    from engine.run import run

    t0 = time.monotonic()
    if isinstance(job.path, list):   # a site: the CLI's orchestrator of several recordings
        from engine.site import components_line, map_site

        site = map_site([str(p) for p in job.path], job.params, job.settings, cache=job.cache,
                        progress=work.progress, cancel=work.cancel)
        notes = list(site.notes) + [line for line in [components_line(site.components)] if line]
        return FinishedRun(job, site.descs, site.topomap, time.monotonic() - t0, list(site.row_starts),
                           [s.name for s in site.sessions], notes)
    out = run(job.path, job.params, settings=job.settings, progress=work.progress, cancel=work.cancel,
              cache=job.cache, metric=True)   # the recording's own odometry / GPS, as the CLI's map
    return FinishedRun(job, out.descs, out.topomap, time.monotonic() - t0)


class RunController(QObject):
    """Starts one run at a time on a ``gui.background.Worker`` and relays its outcome.

    A cancelled or failed run delivers no result, so the current map and decisions stay
    untouched; ``stop`` waits for the thread (call it before the owner dies).
    """

    started = Signal()
    progress = Signal(int, int, str)
    finished = Signal(object)
    failed = Signal(str)
    cancelled = Signal()

    def __init__(self, parent: Optional[QObject] = None) -> None:
        super().__init__(parent)
        self.worker = Worker(self)
        self.worker.progress.connect(self.progress)
        self._ticket: Optional[int] = None
        self.started_at = 0.0

    @property
    def running(self) -> bool:
        return self._ticket is not None

    def start(self, job: RunJob) -> None:
        if self.running:
            raise RuntimeError("a run is already in progress")
        self.started_at = time.monotonic()
        self._ticket = self.worker.submit(lambda work: run_job(job, work), self._on_finished, self._on_failed,
                                          takes_job=True, cancel_running=True)
        self.started.emit()

    def cancel(self) -> None:
        """Ask the run to stop at its next check; ``cancelled`` follows."""
        if self._ticket is None:
            return
        ticket, self._ticket = self._ticket, None
        self.worker.cancel()          # its result, if it still comes, is dropped
        if ticket is not None:
            self.cancelled.emit()

    def stop(self) -> None:
        """Cancel and wait until the thread has ended (call before the owner dies)."""
        self._ticket = None
        self.worker.stop()

    def _on_finished(self, result: FinishedRun) -> None:
        self._ticket = None
        self.finished.emit(result)

    def _on_failed(self, exc: BaseException) -> None:
        self._ticket = None
        if isinstance(exc, Cancelled):
            self.cancelled.emit()
        elif isinstance(exc, InputError):
            self.failed.emit(str(exc))
        else:  # a bug: keep the app alive, say what happened
            traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
            self.failed.emit(f"unexpected error: {exc.__class__.__name__}: {exc}")
