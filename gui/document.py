"""The open document as Qt sees it: ``gui.model.MapDocument`` with its events as Qt signals.

All the logic (map, decisions, similarity, evaluation) lives in the Qt-free model;
this class only turns the model's named events into signals the views connect to.
"""

from __future__ import annotations

from typing import Optional

from PySide6.QtCore import QObject, Signal

from .model.document import STATUSES, LoopKey, LoopRow, MapDocument

__all__ = ["Document", "LoopKey", "LoopRow", "STATUSES"]


class Document(QObject, MapDocument):
    mapReplaced = Signal()        # a new TopoMap: after a run or a parameter change
    loopsChanged = Signal()       # a loop status changed, a manual loop added or removed
    labelsChanged = Signal()
    posesChanged = Signal()
    evaluationChanged = Signal()
    sourceChanged = Signal()      # a new recording opened (or closed)
    estimatedYaw = Signal(object)  # LoopKey whose yaw was estimated from the images
    similarityReady = Signal()    # the similarity matrix of the current map is computed
    journalFailed = Signal(str)   # a decision could not be written to the journal (message)

    def __init__(self, parent: Optional[QObject] = None) -> None:
        QObject.__init__(self, parent)
        MapDocument.__init__(self)

    def _notify(self, event: str, *args) -> None:
        getattr(self, event).emit(*args)
        MapDocument._notify(self, event, *args)
