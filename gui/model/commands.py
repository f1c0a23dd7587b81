"""The user's decisions as undoable commands (plain Python, see ``history``).

Commands address loops and nodes by source frames (``LoopKey``), so a command still
finds its loop after a parameter change rebuilt the map. A bulk action is one
``SetStatuses`` over many loops: one undo step.
"""

from __future__ import annotations

from typing import Mapping, Optional

from .history import Command
from .loop_key import LoopKey


class SetStatuses(Command):
    """Set the status of one or many loops; undo restores each loop's own old status."""

    def __init__(self, old: Mapping[LoopKey, str], new: Mapping[LoopKey, str], text: str = "") -> None:
        self.old = {tuple(k): v for k, v in old.items()}
        self.new = {tuple(k): v for k, v in new.items()}
        self.text = text or _describe(self.new)

    def redo(self, model) -> None:
        model.set_loop_statuses(self.new)

    def undo(self, model) -> None:
        model.set_loop_statuses(self.old)


class AddManualLoop(Command):
    def __init__(self, key: LoopKey, yaw: Optional[float] = None) -> None:
        self.key, self.yaw = tuple(key), yaw
        self.text = f"Add manual loop {self.key[0]}–{self.key[1]}"

    def redo(self, model) -> None:
        model.add_manual_loop(self.key, yaw=self.yaw)

    def undo(self, model) -> None:
        model.remove_loop(self.key)


class RemoveLoop(Command):
    """Removes a (manual) loop; undo puts it back with its attributes."""

    def __init__(self, model, key: LoopKey) -> None:
        self.key = tuple(key)
        self.text = f"Remove loop {self.key[0]}–{self.key[1]}"
        attrs = model.loop_attrs(self.key) or {}
        self.yaw = attrs.get("yaw")
        self.similarity = attrs.get("similarity")
        self.status = attrs.get("status", "manual")

    def redo(self, model) -> None:
        model.remove_loop(self.key)

    def undo(self, model) -> None:
        model.add_manual_loop(self.key, yaw=self.yaw, similarity=self.similarity, status=self.status)


class SetLabel(Command):
    def __init__(self, frame: int, old: str, new: str) -> None:
        self.frame, self.old, self.new = int(frame), old, new
        self.text = f"Name place at frame {frame} '{new}'" if new else f"Clear place name at frame {frame}"

    def redo(self, model) -> None:
        model.set_label(self.frame, self.new)

    def undo(self, model) -> None:
        model.set_label(self.frame, self.old)


def verb(status: str) -> str:
    return {"confirmed": "Confirm", "rejected": "Reject", "auto": "Reset", "candidate": "Reset",
            "manual": "Mark manual"}.get(status, status)


def _describe(new: Mapping[LoopKey, str]) -> str:
    statuses = set(new.values())
    what = verb(statuses.pop()) if len(statuses) == 1 else "Decide"
    if len(new) == 1:
        (a, b), = new.keys()
        return f"{what} loop {a}–{b}"
    return f"{what} {len(new)} loops"
