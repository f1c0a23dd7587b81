"""The Qt face of the undo history: plain commands (``gui.model.commands``) on a QUndoStack.

The decisions themselves are Qt-free command objects; ``QtHistory`` gives the
document a ``push`` that runs them through the window's QUndoStack (its Edit menu,
clean state and title asterisk). Parameter changes stay a QUndoCommand here: they
rebuild the map through the window.
"""

from __future__ import annotations

from typing import Callable

from PySide6.QtGui import QUndoCommand, QUndoStack

from .model.history import Command

# Merge ids: consecutive edits of the same parameter become one undo step.
PARAMS_MERGE_ID = 1001


class _Adapter(QUndoCommand):
    def __init__(self, command: Command, model) -> None:
        super().__init__(command.text)
        self.command, self.model = command, model

    def redo(self) -> None:
        self.command.redo(self.model)

    def undo(self) -> None:
        self.command.undo(self.model)


class QtHistory:
    """What ``MapDocument.history`` needs (``push``), backed by a QUndoStack."""

    def __init__(self, stack: QUndoStack, model) -> None:
        self.stack, self.model = stack, model

    def push(self, command: Command) -> None:
        self.stack.push(_Adapter(command, self.model))


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
