"""The pipeline run off the UI thread: a QObject worker moved to a QThread.

``RunController`` owns the thread and must be stopped (``stop``) before its owner
dies: a QThread destroyed while running aborts the process. A cancelled or failed
run delivers no result, so the current map and decisions stay untouched.
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from PySide6.QtCore import QObject, QThread, Signal, Slot

from engine.errors import Cancelled, InputError
from engine.params import MapParams


@dataclass
class RunJob:
    path: Path
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


class PipelineWorker(QObject):
    progress = Signal(int, int, str)
    finished = Signal(object)     # FinishedRun
    failed = Signal(str)
    cancelled = Signal()

    def __init__(self, job: RunJob, cancel: threading.Event) -> None:
        super().__init__()
        self.job = job
        self.cancel = cancel

    @Slot()
    def run(self) -> None:
        from engine.run import run

        t0 = time.monotonic()
        try:
            out = run(self.job.path, self.job.params, settings=self.job.settings, progress=self._progress,
                      cancel=self.cancel, cache=self.job.cache)
            descs, topomap = out.descs, out.topomap
        except Cancelled:
            self.cancelled.emit()
        except InputError as exc:
            self.failed.emit(str(exc))
        except Exception as exc:  # a bug: keep the app alive, say what happened
            traceback.print_exc(file=sys.stderr)
            self.failed.emit(f"unexpected error: {exc.__class__.__name__}: {exc}")
        else:
            self.finished.emit(FinishedRun(self.job, descs, topomap, time.monotonic() - t0))

    def _progress(self, done: int, total: int, stage: str) -> None:
        self.progress.emit(int(done), int(total), str(stage))


class RunController(QObject):
    """Starts one run at a time and relays its signals to the UI thread."""

    started = Signal()
    progress = Signal(int, int, str)
    finished = Signal(object)
    failed = Signal(str)
    cancelled = Signal()

    def __init__(self, parent: Optional[QObject] = None) -> None:
        super().__init__(parent)
        self._thread: Optional[QThread] = None
        self._worker: Optional[PipelineWorker] = None
        self._cancel: Optional[threading.Event] = None
        self.started_at = 0.0

    @property
    def running(self) -> bool:
        return self._thread is not None

    def start(self, job: RunJob) -> None:
        if self.running:
            raise RuntimeError("a run is already in progress")
        self._cancel = threading.Event()
        thread = QThread()
        worker = PipelineWorker(job, self._cancel)
        worker.moveToThread(thread)
        thread.started.connect(worker.run)
        worker.progress.connect(self.progress)
        worker.finished.connect(self._on_finished)
        worker.failed.connect(self._on_failed)
        worker.cancelled.connect(self._on_cancelled)
        self._thread, self._worker = thread, worker
        self.started_at = time.monotonic()
        thread.start()
        self.started.emit()

    def cancel(self) -> None:
        if self._cancel is not None:
            self._cancel.set()

    def stop(self) -> None:
        """Cancel and wait until the thread has ended (call before the owner dies)."""
        if self._thread is None:
            return
        self.cancel()
        thread = self._thread
        thread.quit()
        thread.wait()
        self._teardown()

    def _end(self) -> None:
        if self._thread is not None:
            self._thread.quit()
            self._thread.wait()
        self._teardown()

    def _teardown(self) -> None:
        if self._worker is not None:
            self._worker.deleteLater()
        if self._thread is not None:
            self._thread.deleteLater()
        self._thread = self._worker = None
        self._cancel = None

    def _stale(self) -> bool:
        """A signal queued by a worker that was already stopped (window closing)."""
        return self._worker is None or self.sender() is not self._worker

    @Slot(object)
    def _on_finished(self, result: FinishedRun) -> None:
        if self._stale():
            return
        cancelled = self._cancel is not None and self._cancel.is_set()
        self._end()
        if cancelled:  # cancel pressed after the last check: the user asked for no result
            self.cancelled.emit()
        else:
            self.finished.emit(result)

    @Slot(str)
    def _on_failed(self, message: str) -> None:
        if self._stale():
            return
        self._end()
        self.failed.emit(message)

    @Slot()
    def _on_cancelled(self) -> None:
        if self._stale():
            return
        self._end()
        self.cancelled.emit()
