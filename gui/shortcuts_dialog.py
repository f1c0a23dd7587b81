"""Help ▸ Keyboard shortcuts."""

from __future__ import annotations

from typing import Optional

from PySide6.QtWidgets import QDialog, QDialogButtonBox, QHeaderView, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget

SHORTCUTS = (
    ("Loops", "C or Y", "Confirm the selected loop"),
    ("Loops", "R or N", "Reject the selected loop"),
    ("Loops", "Backspace or U", "Reset the selected loop to undecided"),
    ("Loops", "J or Page Down", "Next loop"),
    ("Loops", "K or Page Up", "Previous loop"),
    ("Loops", "M", "Add a manual loop between two nodes"),
    ("Loops", "Ctrl+click a node (graph)", "Manual loop between the current node and that node"),
    ("Loops", "Delete", "Remove the selected manual loop"),
    ("Frames", "Left / Right", "Previous / next frame (frame viewer focused)"),
    ("Frames", "Shift+Left / Shift+Right", "Previous / next node"),
    ("Frames", "Home / End", "First / last frame"),
    ("Frames", "Space", "Play / pause"),
    ("Frames", "L", "Name the place of the current node"),
    ("Edit", "Ctrl+Z", "Undo"),
    ("Edit", "Ctrl+Shift+Z or Ctrl+Y", "Redo"),
    ("Run", "F5", "Run the engine"),
    ("Run", "Esc", "Cancel the run"),
    ("File", "Ctrl+O", "Open a recording, bag, folder, session or descriptors"),
    ("File", "Ctrl+S", "Save the session"),
    ("File", "Ctrl+E", "Export the corrected graph (GraphML)"),
)


class ShortcutsDialog(QDialog):
    def __init__(self, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Keyboard shortcuts")
        table = QTableWidget(len(SHORTCUTS), 3)
        table.setHorizontalHeaderLabels(["Area", "Keys", "Action"])
        for r, row in enumerate(SHORTCUTS):
            for c, text in enumerate(row):
                table.setItem(r, c, QTableWidgetItem(text))
        table.verticalHeader().setVisible(False)
        table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        table.horizontalHeader().setStretchLastSection(True)
        table.setEditTriggers(QTableWidget.NoEditTriggers)
        buttons = QDialogButtonBox(QDialogButtonBox.Close)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addWidget(table)
        layout.addWidget(buttons)
        self.resize(620, 560)
