"""Background work off the UI thread: ONE mechanism for every job the app hands off.

``Worker`` runs plain functions on a thread of its own and hands each result (or
error) to a callback on the UI thread. It is used by the pipeline run
(``gui.worker.RunController``), the map re-build on a parameter change, the
similarity matrix, the graph layout, frame decoding (``gui.frame_loader``) and the
pair view's feature matching. Its rules:

* run-latest-only: one job runs at a time; a request made while one runs waits, and a
  newer request replaces a waiting one. The result of a job superseded meanwhile is
  dropped (newest request wins), unless the worker was made with
  ``deliver_superseded=True`` (frame decoding: every decoded frame is worth showing).
* cancel: ``cancel()`` drops the waiting request and the running job's result, and
  sets the running job's ``cancel`` event (``submit(..., takes_job=True)`` hands the
  function a ``Job`` with that event and a ``progress(done, total, stage)`` reporter).
* a job is handed the data it works on, copied on the UI thread (a snapshot): it never
  reads state the user may change while it runs.
* ``stop()`` cancels and waits for the thread (quit + wait); every owner calls it
  before it dies. A thread also ends by itself when no work is left, so an idle app
  holds no thread.

``call_in_background`` is a blocking call (opening and indexing a long recording)
with the window still painting and a busy dialog when it takes a while; it runs on
the same kind of thread.
"""

from __future__ import annotations

import threading
from typing import Callable, Optional, TypeVar

from PySide6.QtCore import QEventLoop, QObject, Qt, QThread, Signal, Slot
from PySide6.QtWidgets import QProgressDialog, QWidget

T = TypeVar("T")
SHOW_AFTER_MS = 300  # a quick open shows no dialog at all


class Job:
    """What a function run with ``takes_job=True`` gets: a cancel event and a progress reporter."""

    def __init__(self, worker: "Worker", ticket: int) -> None:
        self.cancel = threading.Event()
        self._worker, self._ticket = worker, ticket

    def progress(self, done: int, total: int, stage: str) -> None:
        """Report progress (from the worker thread; shown on the UI thread, if still current)."""
        self._worker._progress.emit(self._ticket, int(done), int(total), str(stage))


class _Thread(QThread):
    """Runs the worker's waiting jobs until there is none left, then ends."""

    def __init__(self, worker: "Worker") -> None:
        super().__init__()
        self.worker = worker

    def run(self) -> None:
        while (task := self.worker._take()) is not None:
            ticket, fn, job = task
            value, error = None, None
            try:
                value = fn(job) if job is not None else fn()
            except BaseException as exc:  # handed back to the UI thread
                error = exc
            self.worker._done_running(ticket, value, error)


class Worker(QObject):
    """See the module docstring."""

    progress = Signal(int, int, str)              # the current job's progress (UI thread)
    _progress = Signal(int, int, int, str)        # ticket, done, total, stage (from the thread)
    _result = Signal(int, object, object)         # ticket, value, error (from the thread)

    def __init__(self, parent: Optional[QObject] = None, deliver_superseded: bool = False) -> None:
        super().__init__(parent)
        self.deliver_superseded = deliver_superseded
        self._lock = threading.Lock()
        self._pending: Optional[tuple] = None     # (ticket, fn, takes_job)
        self._running: Optional[tuple[int, Optional[Job]]] = None
        self._active = False                      # a thread is taking jobs
        self._threads: list[_Thread] = []
        self._ticket = 0
        self._undelivered = 0
        self._handlers: dict[int, tuple[Optional[Callable], Optional[Callable]]] = {}
        self._result.connect(self._deliver, Qt.QueuedConnection)
        self._progress.connect(self._relay_progress, Qt.QueuedConnection)

    # -- the UI thread's side ------------------------------------------------------------
    @property
    def busy(self) -> bool:
        """A job waits, runs, or its result is not handed over yet."""
        with self._lock:
            return self._pending is not None or self._running is not None or self._undelivered > 0

    @property
    def ticket(self) -> int:
        """The newest request's ticket (its result is the one delivered)."""
        return self._ticket

    def submit(self, fn: Callable, done: Optional[Callable] = None, failed: Optional[Callable] = None,
               takes_job: bool = False, cancel_running: bool = False) -> int:
        """Run ``fn()`` (``fn(job)`` with ``takes_job``) off the UI thread; ``done(value)`` or
        ``failed(error)`` later on the UI thread. ``cancel_running``: set the running job's
        cancel event (a new run supersedes the old one). Returns the request's ticket."""
        with self._lock:
            self._ticket += 1
            ticket = self._ticket
            if self._pending is not None:
                self._handlers.pop(self._pending[0], None)
            self._pending = (ticket, fn, takes_job)
            self._handlers[ticket] = (done, failed)
            if cancel_running and self._running is not None and self._running[1] is not None:
                self._running[1].cancel.set()
            start = not self._active
            self._active = True
        if start:
            self._threads = [t for t in self._threads if not t.isFinished()]
            thread = _Thread(self)
            self._threads.append(thread)
            thread.start()
        return ticket

    def cancel(self) -> None:
        """Drop the waiting request and the running job's result; ask the running job to stop."""
        with self._lock:
            if self._pending is not None:
                self._handlers.pop(self._pending[0], None)
            self._pending = None
            self._ticket += 1
            if self._running is not None and self._running[1] is not None:
                self._running[1].cancel.set()

    def stop(self) -> None:
        """Cancel, and wait until the threads have ended (call before the owner dies)."""
        self.cancel()
        for thread in self._threads:
            thread.quit()
            thread.wait()
        self._threads = []
        with self._lock:
            self._handlers.clear()
            self._undelivered = 0

    def wait(self, timeout_ms: int = 60_000) -> bool:
        """Process events until nothing runs or waits (for scripts and tests)."""
        from PySide6.QtCore import QCoreApplication, QDeadlineTimer

        deadline = QDeadlineTimer(timeout_ms)
        while self.busy and not deadline.hasExpired():
            for thread in self._threads:
                thread.wait(10)
            QCoreApplication.processEvents()
        return not self.busy

    @Slot(int, object, object)
    def _deliver(self, ticket: int, value, error) -> None:
        with self._lock:
            self._undelivered = max(self._undelivered - 1, 0)
            done, failed = self._handlers.pop(ticket, (None, None))
            current = ticket == self._ticket
        if not current and not self.deliver_superseded:
            return  # superseded by a newer request (or cancelled): the user asked for something else
        if error is not None:
            if failed is None:
                raise error
            failed(error)
        elif done is not None:
            done(value)

    @Slot(int, int, int, str)
    def _relay_progress(self, ticket: int, done: int, total: int, stage: str) -> None:
        if ticket == self._ticket:
            self.progress.emit(done, total, stage)

    # -- the thread's side ---------------------------------------------------------------
    def _take(self) -> Optional[tuple]:
        with self._lock:
            if self._pending is None:
                self._active = False   # no work left: the thread ends
                return None
            ticket, fn, takes_job = self._pending
            self._pending = None
            job = Job(self, ticket) if takes_job else None
            self._running = (ticket, job)
            self._undelivered += 1
            return ticket, fn, job

    def _done_running(self, ticket: int, value, error) -> None:
        with self._lock:
            self._running = None
        try:
            self._result.emit(ticket, value, error)
        except RuntimeError:   # the worker object is gone (its owner died): nothing to tell
            pass


# The name the window's code used for the same thing.
LatestOnly = Worker


def call_in_background(parent: QWidget, label: str, fn: Callable[[], T]) -> T:
    """``fn()`` on a worker thread while the UI thread keeps painting; its value, or its error raised."""
    worker = Worker()
    out: dict = {}
    loop = QEventLoop()
    dialog = QProgressDialog(label, None, 0, 0, parent)  # no cancel: the pass cannot stop halfway
    dialog.setWindowTitle("panotopo")
    dialog.setWindowModality(Qt.ApplicationModal)
    dialog.setMinimumDuration(SHOW_AFTER_MS)
    worker.submit(fn, lambda v: (out.setdefault("value", v), loop.quit()),
                  lambda e: (out.setdefault("error", e), loop.quit()))
    if not out:
        loop.exec()
    worker.stop()   # the thread has ended before the worker goes
    dialog.reset()
    dialog.deleteLater()
    if "error" in out:
        raise out["error"]
    return out.get("value")
