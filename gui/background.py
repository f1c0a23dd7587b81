"""Background work off the UI thread: one small API for every job the window hands off.

* ``LatestOnly``: runs a plain function in a QThread and hands its result (or its
  error) to a callback on the UI thread. One job runs at a time; a request made while
  one runs waits, and a newer request replaces a waiting one; the result of a job that
  was superseded meanwhile is dropped (newest request wins). ``stop`` waits for the
  running job (quit + wait) and must be called before the owner dies.
  The map re-build on a parameter change and the similarity matrix use it.
* ``call_in_background``: one blocking call (opening and indexing a long recording)
  with the window still painting and a busy dialog when it takes a while.

The pipeline run (``gui.worker.RunController``) has its own worker because it reports
progress and can be cancelled midway.
"""

from __future__ import annotations

from typing import Callable, Optional, TypeVar

from PySide6.QtCore import QEventLoop, QObject, Qt, QThread, Slot
from PySide6.QtWidgets import QProgressDialog, QWidget

T = TypeVar("T")
SHOW_AFTER_MS = 300  # a quick open shows no dialog at all


class _Call(QThread):
    def __init__(self, fn: Callable[[], T]) -> None:
        super().__init__()
        self.fn = fn
        self.value = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.value = self.fn()
        except BaseException as exc:  # handed back to the UI thread
            self.error = exc


class LatestOnly(QObject):
    """Run functions off the UI thread, newest request wins (see the module docstring)."""

    def __init__(self, parent: Optional[QObject] = None) -> None:
        super().__init__(parent)
        self._running: Optional[_Call] = None
        self._running_ticket = 0
        self._pending: Optional[tuple[int, Callable, Callable, Optional[Callable]]] = None
        self._ticket = 0
        self._handlers: dict[int, tuple[Callable, Optional[Callable]]] = {}

    @property
    def busy(self) -> bool:
        return self._running is not None or self._pending is not None

    def submit(self, fn: Callable[[], T], done: Callable[[T], None],
               failed: Optional[Callable[[BaseException], None]] = None) -> int:
        """Run ``fn()`` in a thread; ``done(value)`` or ``failed(error)`` later on this thread.

        Returns the request's ticket; only the newest ticket's callbacks are ever called.
        """
        self._ticket += 1
        self._pending = (self._ticket, fn, done, failed)
        if self._running is None:
            self._start_pending()
        return self._ticket

    def cancel(self) -> None:
        """Drop the waiting request and the result of the running one."""
        self._pending = None
        self._ticket += 1

    def stop(self) -> None:
        """Cancel, and wait until the running thread has ended (call before the owner dies)."""
        self.cancel()
        call, self._running = self._running, None
        if call is not None:
            call.quit()
            call.wait()
            call.deleteLater()

    def wait(self, timeout_ms: int = 60_000) -> bool:
        """Process events until nothing runs or waits (for scripts and tests)."""
        from PySide6.QtCore import QCoreApplication, QDeadlineTimer

        deadline = QDeadlineTimer(timeout_ms)
        while self.busy and not deadline.hasExpired():
            if self._running is not None:
                self._running.wait(20)
            QCoreApplication.processEvents()
        return not self.busy

    def _start_pending(self) -> None:
        ticket, fn, done, failed = self._pending
        self._pending = None
        call = _Call(fn)
        self._running, self._running_ticket = call, ticket
        self._handlers = {ticket: (done, failed)}
        call.finished.connect(self._finished, Qt.QueuedConnection)
        call.start()

    @Slot()
    def _finished(self) -> None:
        call, ticket = self._running, self._running_ticket
        if call is None or self.sender() is not call:
            return  # a thread already stopped (and waited for) by stop()
        call.wait()
        self._running = None
        done, failed = self._handlers.pop(ticket, (None, None))
        call.deleteLater()
        if self._pending is not None:
            self._start_pending()
        if ticket != self._ticket:
            return  # superseded by a newer request (or cancelled): the user asked for something else
        if call.error is not None:
            if failed is None:
                raise call.error
            failed(call.error)
        elif done is not None:
            done(call.value)


def call_in_background(parent: QWidget, label: str, fn: Callable[[], T]) -> T:
    call = _Call(fn)
    dialog = QProgressDialog(label, None, 0, 0, parent)  # no cancel: the pass cannot stop halfway
    dialog.setWindowTitle("panotopo")
    dialog.setWindowModality(Qt.ApplicationModal)
    dialog.setMinimumDuration(SHOW_AFTER_MS)
    loop = QEventLoop()
    call.finished.connect(loop.quit)
    call.start()
    if not call.isFinished():
        loop.exec()
    call.wait()  # a QThread must not die while running
    dialog.reset()
    dialog.deleteLater()
    if call.error is not None:
        raise call.error
    return call.value
