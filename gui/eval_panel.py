"""Evaluation panel: the paper's metrics against ground truth, live while curating."""

from __future__ import annotations

from typing import Optional

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QDoubleSpinBox, QFormLayout, QGridLayout, QGroupBox, QLabel, QVBoxLayout, QWidget

from .document import Document

COUNTS = (("tp", "TP", "Detected loops between the same place"),
          ("fp", "FP", "Detected loops between different places (or temporal neighbours)"),
          ("tn", "TN", "Pairs correctly left unjoined"),
          ("fn", "FN", "Same-place pairs without a loop"))
RATIOS = (("precision", "Precision"), ("recall", "Recall"), ("accuracy", "Accuracy"), ("f1", "F1"))


class EvalPanel(QWidget):
    distanceChanged = Signal(float)

    def __init__(self, doc: Document, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.hint = QLabel("Load ground-truth poses (File ▸ Load poses…) to see precision and recall.")
        self.hint.setWordWrap(True)
        self.dist = QDoubleSpinBox()
        self.dist.setRange(0.05, 100.0)
        self.dist.setValue(doc.dist_th)
        self.dist.setSuffix(" m")
        self.dist.setSingleStep(0.25)
        self.dist.setToolTip("Two nodes are the same place when they are this close (the paper: 1.0 m)")
        self.dist.setKeyboardTracking(False)
        self.dist.valueChanged.connect(self._dist_changed)

        box = QGroupBox("Loop closures vs ground truth")
        grid = QGridLayout(box)
        self.values: dict[str, QLabel] = {}
        for i, (key, name, tip) in enumerate(COUNTS):
            title = QLabel(name)
            title.setToolTip(tip)
            value = QLabel("—")
            value.setAlignment(Qt.AlignRight | Qt.AlignVCenter)
            value.setToolTip(tip)
            grid.addWidget(title, i // 2, 2 * (i % 2))
            grid.addWidget(value, i // 2, 2 * (i % 2) + 1)
            self.values[key] = value
        for i, (key, name) in enumerate(RATIOS):
            value = QLabel("—")
            value.setAlignment(Qt.AlignRight | Qt.AlignVCenter)
            grid.addWidget(QLabel(name), 2 + i // 2, 2 * (i % 2))
            grid.addWidget(value, 2 + i // 2, 2 * (i % 2) + 1)
            self.values[key] = value
        self.events = QLabel("—")
        self.events.setToolTip("Revisit events with at least one correct loop")
        grid.addWidget(QLabel("Revisits found"), 4, 0)
        grid.addWidget(self.events, 4, 1, 1, 3)

        form = QFormLayout()
        form.addRow("Same place within", self.dist)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.hint)
        layout.addLayout(form)
        layout.addWidget(box)
        layout.addStretch(1)
        doc.evaluationChanged.connect(self.refresh)
        doc.posesChanged.connect(self.refresh)
        self.refresh()

    def refresh(self) -> None:
        ev = self.doc.evaluation
        self.hint.setVisible(ev is None)
        for key, _name, *_ in COUNTS + RATIOS:
            if ev is None:
                self.values[key].setText("—")
            elif key in ("tp", "fp", "tn", "fn"):
                self.values[key].setText(f"<b>{getattr(ev, key)}</b>")
            else:
                self.values[key].setText(f"<b>{ev.ratio_text(key, percent=True)}</b>")  # "n/a" if undefined
        if ev is None:
            self.events.setText("—")
        else:
            self.events.setText(f"{getattr(ev, 'events_found', 0)} / {getattr(ev, 'events_total', 0)}")

    def _dist_changed(self, value: float) -> None:
        self.doc.dist_th = float(value)
        self.doc.evaluate()
