"""Help ▸ Keyboard shortcuts: the shortcut table (gui.model.keys), as the app uses it."""

from __future__ import annotations

from typing import Iterable, Optional

from PySide6.QtWidgets import QDialog, QDialogButtonBox, QHeaderView, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget

from .model.keys import SHORTCUTS, Shortcut


class ShortcutsDialog(QDialog):
    def __init__(self, table: Iterable[Shortcut] = SHORTCUTS, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Keyboard shortcuts")
        rows = [(s.area, s.shown, s.text) for s in table]
        widget = QTableWidget(len(rows), 3)
        widget.setHorizontalHeaderLabels(["Area", "Keys", "Action"])
        for r, row in enumerate(rows):
            for c, text in enumerate(row):
                widget.setItem(r, c, QTableWidgetItem(text))
        widget.verticalHeader().setVisible(False)
        widget.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        widget.horizontalHeader().setStretchLastSection(True)
        widget.setEditTriggers(QTableWidget.NoEditTriggers)
        buttons = QDialogButtonBox(QDialogButtonBox.Close)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addWidget(widget)
        layout.addWidget(buttons)
        self.resize(640, 600)
