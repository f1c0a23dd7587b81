"""Node panel: the node of the current frame, its place name and the loops that touch it."""

from __future__ import annotations

from typing import Optional

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (QFormLayout, QGroupBox, QHBoxLayout, QLabel, QLineEdit, QListWidget,
                               QListWidgetItem, QPushButton, QSizePolicy, QVBoxLayout, QWidget)

from engine.session_fields import LABEL_MAX

from .document import Document
from .style import STATUS_COLORS


class NodePanel(QWidget):
    labelEdited = Signal(int, str)      # node's source frame, new place name
    loopActivated = Signal(object)      # LoopKey
    addLoopRequested = Signal(int)      # node index: open the manual loop dialog from here

    def __init__(self, doc: Document, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.node_index: Optional[int] = None

        self.title = QLabel("No map yet")
        self.details = QLabel("")
        self.details.setTextInteractionFlags(Qt.TextSelectableByMouse)
        # Long details wrap instead of widening the left column (1280-px screens, issue 14 defect 4).
        for label in (self.title, self.details):
            label.setWordWrap(True)
            label.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.name = QLineEdit()
        self.name.setMaxLength(LABEL_MAX)   # a longer name would make the session refuse to load
        self.name.setPlaceholderText("e.g. kitchen, lab door, crossing A")
        self.name.setToolTip("Place name of this node (Enter to apply; undo with Ctrl+Z)")
        self.name.returnPressed.connect(self._apply_name)
        self.apply_button = QPushButton("Name")
        self.apply_button.setToolTip("Apply the place name (Enter)")
        self.apply_button.clicked.connect(self._apply_name)
        self.loops = QListWidget()
        self.loops.setToolTip("Loops at this node: click one to look at it")
        self.loops.itemClicked.connect(lambda item: self.loopActivated.emit(item.data(Qt.UserRole)))
        self.add_button = QPushButton("+ Manual loop from this node…")
        self.add_button.setToolTip("Join this node to another node that is the same place (M)")
        self.add_button.clicked.connect(lambda: self.node_index is not None
                                        and self.addLoopRequested.emit(self.node_index))

        name_row = QHBoxLayout()
        name_row.addWidget(self.name, 1)
        name_row.addWidget(self.apply_button)
        box = QGroupBox("Current node")
        form = QFormLayout(box)
        form.addRow(self.title)
        form.addRow(self.details)
        form.addRow("Place name", name_row)
        form.addRow(QLabel("Loops at this node"))
        form.addRow(self.loops)
        form.addRow(self.add_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 0, 4, 4)
        layout.addWidget(box)
        self._set_enabled(False)

        doc.mapReplaced.connect(self.refresh)
        doc.loopsChanged.connect(self.refresh)
        doc.labelsChanged.connect(self.refresh)

    def show_node(self, k: Optional[int]) -> None:
        self.node_index = k
        self.refresh()

    def refresh(self) -> None:
        k = self.node_index
        if not self.doc.has_map or k is None or not (0 <= k < self.doc.node_count()):
            self.title.setText("No map yet" if not self.doc.has_map else "No node")
            self.details.setText("")
            self.name.setText("")
            self.loops.clear()
            self._set_enabled(False)
            return
        self._set_enabled(True)
        node = self.doc.node_id(k)
        d = self.doc.node_data(node)
        self.title.setText(f"<b>{node}</b> — node {k + 1} of {self.doc.node_count()}")
        xy = f", at ({float(d['x']):.1f}, {float(d['y']):.1f}) m" if "x" in d and self.doc.poses is not None else ""
        recording = f"{d['session']}, " if d.get("session") else ""
        self.details.setText(f"{recording}frame {d['frame']}, t = {float(d['stamp']):.2f} s, "
                             f"shift {int(d.get('shift', 0))} columns{xy}")
        if not self.name.hasFocus():
            self.name.setText(str(d.get("label", "") or ""))
        self.loops.clear()
        for row in self.doc.loop_rows():
            if k not in (row.index_u, row.index_v):
                continue
            other = row.v if row.index_u == k else row.u
            item = QListWidgetItem(f"↔ {other}   similarity {row.similarity:.3f}   {row.status}")
            item.setData(Qt.UserRole, row.key)
            color = QColor(STATUS_COLORS.get(row.status, "#000"))
            color.setAlpha(60)
            item.setBackground(QBrush(color))
            self.loops.addItem(item)
        if self.loops.count() == 0:
            placeholder = QListWidgetItem("(none)")
            placeholder.setFlags(Qt.NoItemFlags)
            self.loops.addItem(placeholder)

    def _apply_name(self) -> None:
        if self.node_index is None or not self.doc.has_map:
            return
        self.labelEdited.emit(self.doc.node_place(self.node_index), self.name.text().strip())

    def _set_enabled(self, on: bool) -> None:
        for w in (self.name, self.apply_button, self.loops, self.add_button):
            w.setEnabled(on)
