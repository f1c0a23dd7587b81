"""Add a manual loop: two node pickers, each showing the node's frame, time and name.

The second node proposed is the node most like the first one (by descriptor
similarity) outside its temporal neighbourhood, never a neighbour: a loop between
nodes a few steps apart on the path joins a place to itself, not a revisit. Picking
such a pair is allowed but warned about; two nodes already joined cannot be picked.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from PySide6.QtWidgets import QDialog, QDialogButtonBox, QFormLayout, QLabel, QSpinBox, QVBoxLayout, QWidget

from .document import Document


def temporal_gap(doc: Document) -> int:
    """Nodes closer than this on the path are temporal neighbours, not a revisit.

    The map's ``neighbor_node_num`` (default 5): the same distance the loop
    detection itself leaves out as neighbours.
    """
    return max(int(getattr(doc.params, "neighbor_node_num", 5) or 5), 2)


def proposed_partner(doc: Document, first: int) -> int:
    """The node to propose with ``first``: the most similar one that is not a temporal neighbour.

    Without descriptors, the node farthest away in time. Never ``first`` or a neighbour
    when the map has any other node.
    """
    n = doc.node_count()
    gap = temporal_gap(doc)
    far = np.abs(np.arange(n) - first) >= gap
    joined = _joined(doc, first)
    if (far & ~joined).any():   # never a pair already joined: OK would be disabled (issue 43, defect 4)
        far &= ~joined
    if not far.any():
        far = np.arange(n) != first
        if not far.any():
            return first
    sim = doc.similarity()
    if sim is not None and sim.shape[0] == n:
        return int(np.argmax(np.where(far, sim[first], -np.inf)))
    return int(np.argmax(np.where(far, np.abs(np.arange(n) - first), -1)))


def _joined(doc: Document, first: int) -> np.ndarray:
    """(n,) True for the nodes already joined to ``first`` (by the path or a loop)."""
    n = doc.node_count()
    out = np.zeros(n, bool)
    g = doc.topomap.graph
    for other in g.neighbors(doc.node_id(first)):
        out[int(g.nodes[other]["index"])] = True
    return out


class ManualLoopDialog(QDialog):
    def __init__(self, doc: Document, first: int = 0, second: Optional[int] = None,
                 parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.setWindowTitle("Add manual loop")
        n = doc.node_count()
        # Every widget _update touches exists before the first valueChanged can call it.
        self.a_info, self.b_info = QLabel(), QLabel()
        # One short line, in room kept for it: a long wrapped warning squashed both node
        # fields to a few pixels (issue 43, defect 4); the full reason is in its tooltip.
        self.warning = QLabel()
        self.warning.setStyleSheet("color: #c0392b")
        self.warning.setMinimumHeight(self.warning.fontMetrics().height() + 4)
        self.buttons = QDialogButtonBox(QDialogButtonBox.Ok | QDialogButtonBox.Cancel)
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        self.a = QSpinBox()
        self.b = QSpinBox()
        for box in (self.a, self.b):
            box.setRange(0, max(n - 1, 0))
            box.setPrefix("n")
        first = int(np.clip(first, 0, max(n - 1, 0)))
        self.a.setValue(first)
        self.b.setValue(second if second is not None else (proposed_partner(doc, first) if n else 0))
        for box in (self.a, self.b):
            box.valueChanged.connect(self._update)
        form = QFormLayout()
        form.addRow("First node", self.a)
        form.addRow("", self.a_info)
        form.addRow("Second node", self.b)
        form.addRow("", self.b_info)
        layout = QVBoxLayout(self)
        layout.setSizeConstraint(QVBoxLayout.SetMinimumSize)   # the dialog grows; fields never shrink
        layout.addWidget(QLabel("Join two nodes that are the same place:"))
        layout.addLayout(form)
        layout.addWidget(self.warning)
        layout.addWidget(self.buttons)
        self._update()

    def nodes(self) -> tuple[int, int]:
        return self.a.value(), self.b.value()

    def _describe(self, k: int) -> str:
        d = self.doc.node_data(self.doc.node_id(k))
        label = f" “{d['label']}”" if d.get("label") else ""
        recording = f"{d['session']}, " if d.get("session") else ""   # a site: which recording
        return f"{recording}frame {d['frame']}, t = {float(d['stamp']):.1f} s{label}"

    def _update(self) -> None:
        if self.doc.node_count() == 0:
            self.buttons.button(QDialogButtonBox.Ok).setEnabled(False)
            return
        a, b = self.nodes()
        self.a_info.setText(self._describe(a))
        self.b_info.setText(self._describe(b))
        g = self.doc.topomap.graph
        problem, caution, why = "", "", ""
        if a == b:
            problem = "Choose two different nodes."
        elif g.has_edge(self.doc.node_id(a), self.doc.node_id(b)):
            problem = "These nodes are already joined."
            why = "The path or a loop joins them already: choose another second node."
        elif abs(a - b) < temporal_gap(self.doc) and (self.doc.node_data(self.doc.node_id(a)).get("session")
                                                       == self.doc.node_data(self.doc.node_id(b)).get("session")):
            caution = f"Temporal neighbours ({abs(a - b)} steps apart): not a revisit."
            why = (f"n{a} and n{b} are {abs(a - b)} steps apart on the path: a loop between them joins a "
                   "place to itself, not a revisit. Add it only if you are sure.")
        self.warning.setText(problem or caution)
        self.warning.setToolTip(why)
        ok = self.buttons.button(QDialogButtonBox.Ok)
        ok.setEnabled(not problem)
        ok.setToolTip(problem)   # a disabled OK says why
