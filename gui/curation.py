"""Curation: decisions on loops, manual loops, place names and the selection shared by the views.

``Curation`` turns keys and clicks into the model's undoable commands
(``gui.model.commands`` through ``gui.model.queue.ReviewQueue``) and keeps the table,
the pair view, the graph, the matrix and the frame viewer on the same loop.
"""

from __future__ import annotations

from typing import Optional

from PySide6.QtCore import QObject, Qt
from PySide6.QtWidgets import QInputDialog, QLineEdit

from engine.errors import InputError
from engine.session_fields import LABEL_MAX

from .document import LoopKey
from .manual_loop_dialog import ManualLoopDialog
from .model import commands as edits
from .pair_evidence import pair_yaw


class Curation(QObject):
    """Decisions and the selection the views share (see the module docstring)."""

    def __init__(self, window) -> None:
        super().__init__(window)
        self.w = window   # the views, the status bar and the messages it shows

    def selected_key(self) -> Optional[LoopKey]:
        return self.w.loop_table.selected_key() or self.w.pair_view.key

    def decide(self, status: str) -> None:
        """Confirm, reject or reset the loops selected in the table (one undo step), nothing else.

        A decision applies only to rows the user sees selected; after it the selection moves
        to the row below, and stays on the last row (no wrap: issue 14, defect 1).
        """
        keys = self.w.loop_table.selected_keys()
        if not keys:
            self.w.statusBar().showMessage("Select a loop in the table first", 4000)
            return
        self._decide_keys(keys, status, order=self.w.loop_table.visible_keys())

    def decide_pair(self, status: str) -> None:
        """A decision button of the pair view: the loop shown there."""
        if self.w.pair_view.key is not None:
            self._decide_keys([self.w.pair_view.key], status, order=self.w.loop_table.visible_keys())

    def _decide_keys(self, keys: list, status: str, order: list) -> None:
        manual = [k for k in keys if self.w.doc.status_of(k) == "manual"]
        if len(manual) == len(keys):
            self.w.statusBar().showMessage("A manual loop has no decision to change: remove it instead (Delete)", 5000)
            return
        self.w.queue.select(keys)
        self.w.queue.advance_after_decision = self.w.advance_after_decision
        changed = self.w.queue.decide(status, order=order)
        self.w.loop_table.select_keys(self.w.queue.selected)
        if len(keys) > 1:
            self.w.statusBar().showMessage(f"{edits.verb(status)}: {changed} of {len(keys)} selected loops "
                                         "changed (one undo step)", 5000)

    def next_undecided(self) -> None:
        """Select the next loop nobody has decided on (in the order shown; wraps to the top)."""
        current = self.w.loop_table.selected_key()
        key = self.w.queue.next_undecided(after=current, order=self.w.loop_table.visible_keys())
        if key is None:  # none shown: the filter may hide them
            key = self.w.queue.next_undecided(after=current)
        if key is None:
            self.w.statusBar().showMessage("Every loop is decided", 5000)
            return
        self.w.loop_table.select_key(key)

    def focus_queue(self) -> None:
        """The keyboard to the review queue, on its current row (the first when none is)."""
        self.w.loop_table.view.setFocus(Qt.ShortcutFocusReason)
        if self.w.loop_table.selected_key() is None:
            self.select_first_loop()

    def reject_below(self) -> None:
        """Reject every undecided loop ranked below the selected one (one undo step)."""
        key = self.w.loop_table.selected_key()
        if key is None:
            self.w.statusBar().showMessage("Select the weakest loop you judged good first", 5000)
            return
        n = self.w.queue.reject_below(self.w.queue.evidence_of(key))
        self.w.loop_table.select_key(key)
        self.w.statusBar().showMessage(f"Rejected {n} undecided loops ranked below the selected one "
                                     "(Ctrl+Z undoes them all)", 8000)

    def add_manual_loop(self, key: LoopKey) -> bool:
        try:
            yaw = pair_yaw(self.w.doc, self.w.frames, tuple(key), self.w.pair_view.match_cache.peek)  # issue 14, 8
            self.w.doc.push(edits.AddManualLoop(tuple(key), yaw))
        except InputError as exc:
            self.w.warn(str(exc))
            return False
        self.w.loop_table.select_key(tuple(key))
        return True

    def _ctrl_click_loop(self, a: int, b: int) -> None:
        """Ctrl+click in the graph: a manual loop from the current node, after a question (defect 10)."""
        same_recording = self.w.doc.site is None or (
            self.w.doc.node_data(self.w.doc.node_id(a)).get("session") == self.w.doc.node_data(self.w.doc.node_id(b)).get("session"))
        if abs(a - b) < 2 and same_recording:
            self.w.statusBar().showMessage("Neighbouring nodes are already joined by the path", 5000)
            return
        lo, hi = min(a, b), max(a, b)
        if not self.w._ask_yes_no("Add manual loop", f"Join n{lo} and n{hi} as the same place (a manual loop)?"):
            return
        if self.add_manual_loop(self.w.doc.key_of_nodes(a, b)):
            self.w.statusBar().showMessage(f"Manual loop n{lo} ↔ n{hi} added (Ctrl+Z to undo)", 5000)

    def remove_manual_loop(self, key: LoopKey) -> None:
        attrs = self.w.doc.loop_attrs(key)
        if attrs is None or attrs.get("status") != "manual":
            self.w.statusBar().showMessage("Only manual loops can be removed; reject a detected loop instead", 5000)
            return
        self.w.doc.push(edits.RemoveLoop(self.w.doc, key))

    def remove_selected_manual(self) -> None:
        key = self.selected_key()
        if key is not None:
            self.remove_manual_loop(key)

    def manual_loop_dialog(self, first: Optional[int] = None, second: Optional[int] = None) -> None:
        if not self.w.doc.has_map:
            return
        if first is None:
            first = self.w.doc.node_at_or_before(max(self.w.frame_viewer.current_frame, 0)) or 0
        dialog = ManualLoopDialog(self.w.doc, first, second, self.w)
        if dialog.exec() == ManualLoopDialog.Accepted:
            a, b = dialog.nodes()
            self.add_manual_loop(self.w.doc.key_of_nodes(a, b))

    def name_place_dialog(self) -> None:
        if not self.w.doc.has_map:
            return
        k = self.w.doc.node_at_or_before(max(self.w.frame_viewer.current_frame, 0))
        frame = self.w.doc.node_place(k)
        old = self.w.doc.label_of_frame(frame)
        dialog = QInputDialog(self.w)
        dialog.setWindowTitle("Name this place")
        dialog.setLabelText(f"Place name of node n{k} ({self.w.doc.place_text(frame)}):")
        dialog.setTextValue(old)
        field = dialog.findChild(QLineEdit)
        if field is not None:
            field.setMaxLength(LABEL_MAX)   # enforced where it is typed (issue 43, defect 16)
        if dialog.exec() == QInputDialog.Accepted:
            self.set_label(frame, dialog.textValue().strip())

    def set_label(self, frame: int, label: str) -> None:
        old = self.w.doc.label_of_frame(frame)
        if len(label) > LABEL_MAX:
            self.w.warn(f"A place name has at most {LABEL_MAX} characters; this one has {len(label)}")
            return
        if label != old:
            self.w.doc.push(edits.SetLabel(frame, old, label))

    def select_loop(self, key: LoopKey) -> None:
        if not self.w.loop_table.select_key(key):
            self.select_pair_key(key)

    def select_pair(self, a: int, b: int) -> None:
        """A pair of nodes clicked in the matrix: its loop, or the pair itself."""
        key = self.w.doc.key_of_nodes(a, b)
        if self.w.doc.loop_attrs(key) is not None:
            self.w.loop_table.select_key(key)
        else:
            self.select_pair_key(key)
            self.w.statusBar().showMessage(
                f"n{a} ↔ n{b} is not a loop: “Add as manual loop” in the pair view joins them", 6000)

    def select_pair_key(self, key: LoopKey) -> None:
        self.w.loop_table.select_key(None)
        self.w.pair_view.show_pair(key)
        self.w.graph_view.set_selected_loop(key)
        self.w.similarity_view.set_selected_pair(key)

    def _loop_selected(self, key: Optional[LoopKey]) -> None:
        if key is None:
            return
        self.w.pair_view.show_pair(key)
        self.w.graph_view.set_selected_loop(key)
        self.w.similarity_view.set_selected_pair(key)
        self.w.frame_viewer.show_frame(key[0])

    def show_node(self, k: int) -> None:
        self.w.frame_viewer.show_frame(self.w.doc.node_place(k))

    def _sync_current_node(self) -> None:
        self._frame_changed(self.w.frame_viewer.current_frame)

    def _frame_changed(self, frame: int) -> None:
        k = self.w.doc.node_at_or_before(frame) if self.w.doc.has_map else None
        self.w.graph_view.set_current_node(k)
        if k != self.w.node_panel.node_index:
            self.w.node_panel.show_node(k)

    def select_first_loop(self) -> bool:
        """Select the first candidate in the table (if none is selected); False when there is none."""
        rows = self.w.loop_table.proxy.rowCount()
        if rows and self.w.loop_table.selected_key() is None:
            self.w.loop_table.step(1)
        return rows > 0
