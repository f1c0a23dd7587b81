"""Undoable edits (QUndoCommand): every decision and every edit goes through one.

Commands address loops and nodes by source frames (see ``gui.document``), so a
command still finds its loop after a parameter change rebuilt the map.
"""

from __future__ import annotations

from typing import Callable, Optional

from PySide6.QtGui import QUndoCommand

from .document import Document, LoopKey

# Merge ids: consecutive edits of the same parameter become one undo step.
PARAMS_MERGE_ID = 1001


class SetLoopStatus(QUndoCommand):
    def __init__(self, doc: Document, key: LoopKey, old: str, new: str) -> None:
        super().__init__(f"{_verb(new)} loop {key[0]}–{key[1]}")
        self.doc, self.key, self.old, self.new = doc, key, old, new

    def redo(self) -> None:
        self.doc.set_loop_status(self.key, self.new)

    def undo(self) -> None:
        self.doc.set_loop_status(self.key, self.old)


class AddManualLoop(QUndoCommand):
    def __init__(self, doc: Document, key: LoopKey, yaw: Optional[float] = None) -> None:
        super().__init__(f"Add manual loop {key[0]}–{key[1]}")
        self.doc, self.key, self.yaw = doc, key, yaw

    def redo(self) -> None:
        self.doc.add_manual_loop(self.key, yaw=self.yaw)

    def undo(self) -> None:
        self.doc.remove_loop(self.key)


class RemoveLoop(QUndoCommand):
    """Removes a (manual) loop; undo puts it back with its attributes."""

    def __init__(self, doc: Document, key: LoopKey) -> None:
        super().__init__(f"Remove loop {key[0]}–{key[1]}")
        self.doc, self.key = doc, key
        attrs = doc.loop_attrs(key) or {}
        self.yaw = attrs.get("yaw")
        self.similarity = attrs.get("similarity")
        self.status = attrs.get("status", "manual")

    def redo(self) -> None:
        self.doc.remove_loop(self.key)

    def undo(self) -> None:
        self.doc.add_manual_loop(self.key, yaw=self.yaw, similarity=self.similarity, status=self.status)


class SetLabel(QUndoCommand):
    def __init__(self, doc: Document, frame: int, old: str, new: str) -> None:
        super().__init__(f"Name place at frame {frame} '{new}'" if new else f"Clear place name at frame {frame}")
        self.doc, self.frame, self.old, self.new = doc, frame, old, new

    def redo(self) -> None:
        self.doc.set_label(self.frame, self.new)

    def undo(self) -> None:
        self.doc.set_label(self.frame, self.old)


class ChangeParams(QUndoCommand):
    """A parameter change; ``apply`` rebuilds the map (keeping the decisions)."""

    def __init__(self, apply: Callable[[object, object], None], old, new, field: str) -> None:
        super().__init__(f"Change {field}")
        self.apply, self.old, self.new, self.field = apply, old, new, field

    def id(self) -> int:
        return PARAMS_MERGE_ID

    def mergeWith(self, other: QUndoCommand) -> bool:
        if not isinstance(other, ChangeParams) or other.field != self.field:
            return False
        self.new = other.new
        return True

    def redo(self) -> None:
        self.apply(self.old, self.new)

    def undo(self) -> None:
        self.apply(self.new, self.old)


def _verb(status: str) -> str:
    return {"confirmed": "Confirm", "rejected": "Reject", "auto": "Reset", "manual": "Mark manual"}.get(status, status)
