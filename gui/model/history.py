"""Undo and redo of plain command objects (no Qt).

A ``Command`` knows how to apply itself to a model (``redo``) and how to take itself
back (``undo``). ``History`` is the undo stack: ``push`` applies and records. A bulk
action is one command over many loops, so it is one undo step. The Qt window shows
the same commands through a QUndoStack adapter (``gui.commands.QtHistory``), which
offers the same ``push``.
"""

from __future__ import annotations

from typing import Callable, Optional


class Command:
    """One undoable edit. Subclasses set ``text`` and implement ``redo``/``undo``."""

    text = ""

    def redo(self, model) -> None:
        raise NotImplementedError

    def undo(self, model) -> None:
        raise NotImplementedError


class History:
    """A linear undo stack over one model; ``changed`` callbacks run after every move."""

    def __init__(self, model) -> None:
        self.model = model
        self._done: list[Command] = []
        self._undone: list[Command] = []
        self._clean_index: Optional[int] = 0
        self.changed: list[Callable[[], None]] = []

    def push(self, command: Command) -> None:
        """Apply ``command`` and record it; an edit after undo drops the redo branch."""
        command.redo(self.model)
        self._done.append(command)
        if self._clean_index is not None and self._clean_index > len(self._done) - 1:
            self._clean_index = None  # the clean state was on the dropped branch
        self._undone.clear()
        self._changed()

    def undo(self) -> bool:
        return self._move(self._done, self._undone, "undo")

    def redo(self) -> bool:
        return self._move(self._undone, self._done, "redo")

    def _move(self, source: list, target: list, how: str) -> bool:
        """Take the top command of ``source``, run its ``how``, put it on ``target``."""
        if not source:
            return False
        command = source.pop()
        getattr(command, how)(self.model)
        target.append(command)
        self._changed()
        return True

    def can_undo(self) -> bool:
        return bool(self._done)

    def can_redo(self) -> bool:
        return bool(self._undone)

    def undo_text(self) -> str:
        return self._done[-1].text if self._done else ""

    def __len__(self) -> int:
        return len(self._done)

    def clear(self) -> None:
        self._done.clear()
        self._undone.clear()
        self._clean_index = 0
        self._changed()

    def set_clean(self) -> None:
        self._clean_index = len(self._done)
        self._changed()

    def is_clean(self) -> bool:
        return self._clean_index == len(self._done)

    def _changed(self) -> None:
        for fn in list(self.changed):
            fn()
