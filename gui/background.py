"""Run one blocking call off the UI thread while the window keeps painting.

Opening a long 4K video or a large bag needs one pass over it (exact stamps, the
message index). ``call_in_background`` runs that pass in a QThread, spins a local
event loop until it ends, and shows an application-modal busy dialog when it takes
longer than a moment. Errors raised by the call are raised again in the caller.
"""

from __future__ import annotations

from typing import Callable, TypeVar

from PySide6.QtCore import QEventLoop, Qt, QThread
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
        except BaseException as exc:  # handed back to the UI thread, raised there
            self.error = exc


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
