"""Add a manual loop: two node pickers, each showing the node's frame, time and name."""

from __future__ import annotations

from typing import Optional

from PySide6.QtWidgets import QDialog, QDialogButtonBox, QFormLayout, QLabel, QSpinBox, QVBoxLayout, QWidget

from .document import Document


class ManualLoopDialog(QDialog):
    def __init__(self, doc: Document, first: int = 0, second: Optional[int] = None,
                 parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.setWindowTitle("Add manual loop")
        n = doc.node_count()
        self.a = QSpinBox()
        self.b = QSpinBox()
        self.a_info, self.b_info = QLabel(), QLabel()
        for box in (self.a, self.b):
            box.setRange(0, max(n - 1, 0))
            box.setPrefix("n")
            box.valueChanged.connect(self._update)
        self.a.setValue(first)
        self.b.setValue(second if second is not None else min(first + 2, max(n - 1, 0)))
        self.warning = QLabel()
        self.warning.setStyleSheet("color: #c0392b")
        self.buttons = QDialogButtonBox(QDialogButtonBox.Ok | QDialogButtonBox.Cancel)
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        form = QFormLayout()
        form.addRow("First node", self.a)
        form.addRow("", self.a_info)
        form.addRow("Second node", self.b)
        form.addRow("", self.b_info)
        layout = QVBoxLayout(self)
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
        return f"frame {d['frame']}, t = {float(d['stamp']):.1f} s{label}"

    def _update(self) -> None:
        if self.doc.node_count() == 0:
            return
        a, b = self.nodes()
        self.a_info.setText(self._describe(a))
        self.b_info.setText(self._describe(b))
        g = self.doc.topomap.graph
        problem = ""
        if a == b:
            problem = "Choose two different nodes."
        elif g.has_edge(self.doc.node_id(a), self.doc.node_id(b)):
            problem = "These nodes are already joined."
        self.warning.setText(problem)
        self.buttons.button(QDialogButtonBox.Ok).setEnabled(not problem)
