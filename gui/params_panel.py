"""Parameters panel: descriptor settings (need a new describe) and map parameters (instant).

Map parameter edits emit ``paramsEdited(field, MapParams)``; the window rebuilds
the map from the cached descriptors at once. Descriptor and interval edits emit
``describeEdited`` and are applied by the Run button (a new describe, cached).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Optional

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout, QGroupBox, QHBoxLayout,
                               QPushButton, QSpinBox, QVBoxLayout, QWidget)

from engine import params as params_module
from engine.params import MapParams

METHOD_TIPS = {
    "simple": "Simple threshold on unshifted descriptors (paper baseline)",
    "shift-simple": "Panorama shift, then a simple threshold",
    "ours": "Panorama shift + spatial consistency check (the paper's method)",
}


class ParamsPanel(QWidget):
    paramsEdited = Signal(str, object)   # field name, new MapParams
    describeEdited = Signal()
    runRequested = Signal()
    calibrateRequested = Signal()        # thresholds of the paper's methods from the recording

    def __init__(self, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self._params = MapParams()
        self._updating = False

        self.descriptor = QComboBox()
        self.descriptor.setToolTip("Visual place recognition descriptor (changing it describes the recording again)")
        try:
            from engine.descriptors import names

            self.descriptor.addItems(names())
        except Exception:  # the registry must never keep the window from opening
            self.descriptor.addItem("effnet-vlad")
        self.interval = QDoubleSpinBox()
        self.interval.setRange(0.05, 60.0)
        self.interval.setSingleStep(0.25)
        self.interval.setValue(1.0)
        self.interval.setSuffix(" s")
        self.interval.setToolTip("Sampling interval of the recording (the paper: 1.0 s)")
        self.run_button = QPushButton("Run")
        self.run_button.setToolTip("Describe the recording with these settings and build the map (F5)")
        self.run_button.clicked.connect(self.runRequested)
        self.descriptor.currentIndexChanged.connect(lambda _: self._describe_changed())
        self.interval.valueChanged.connect(lambda _: self._describe_changed())

        self.method = QComboBox()
        for m in params_module.METHODS:  # read at run time: methods may be added
            self.method.addItem(m, m)
            self.method.setItemData(self.method.count() - 1, METHOD_TIPS.get(m, m), 3)
        self.method.setToolTip("Loop detection method (Table I of the paper)")
        self.node_sim_th = _double(0.0, 1.0, 0.01, "Similarity above which a frame is merged into the current node "
                                                   "(verified: calibrated from the recording unless you change it)")
        self.loop_sim_th = _double(-1.0, 1.0, 0.01, "Similarity above which two nodes may be the same place")
        self.window_size = _int(1, 100, "Nodes per sliding window of the spatial consistency check")
        self.count_th = _int(0, 100, "A window is a candidate when more than this many of its nodes match")
        self.neighbor_node_num = _int(0, 1000, "Temporal neighbours of the query that windows must avoid")
        self.calibrate_button = QPushButton("Thresholds from recording")
        self.calibrate_button.setToolTip("simple / shift-simple / ours: set the node and loop thresholds "
                                         "from this recording's own similarities (undoable)")
        self.calibrate_button.clicked.connect(self.calibrateRequested)
        self.long_runs = QCheckBox("Long runs")
        self.long_runs.setToolTip("verified-rules: also look for stretches driven twice with a lateral offset "
                                  "(finds more returns, rarely a false loop)")

        self.method.currentIndexChanged.connect(lambda _: self._edited("method"))
        for name in ("node_sim_th", "loop_sim_th", "window_size", "count_th", "neighbor_node_num"):
            getattr(self, name).valueChanged.connect(lambda _, n=name: self._edited(n))
        self.long_runs.toggled.connect(lambda _: self._edited("long_runs"))

        describe_box = QGroupBox("Descriptors")
        form = QFormLayout(describe_box)
        form.addRow("Descriptor", self.descriptor)
        form.addRow("Interval", self.interval)
        row = QHBoxLayout()
        row.addStretch(1)
        row.addWidget(self.run_button)
        form.addRow(row)
        map_box = QGroupBox("Map (applied at once)")
        form = QFormLayout(map_box)
        form.addRow("Method", self.method)
        form.addRow("Node similarity", self.node_sim_th)
        form.addRow("Loop similarity", self.loop_sim_th)
        form.addRow("Window size", self.window_size)
        form.addRow("Count threshold", self.count_th)
        form.addRow("Neighbour nodes", self.neighbor_node_num)
        form.addRow("", self.long_runs)
        form.addRow("", self.calibrate_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(describe_box)
        layout.addWidget(map_box)
        layout.addStretch(1)
        self.set_params(MapParams(), {"node_sim_th": 0.8, "loop_sim_th": 0.55})

    # -- values ----------------------------------------------------------------------
    def params(self) -> MapParams:
        return self._params

    def set_params(self, params: MapParams, defaults: Optional[dict] = None) -> None:
        """Show ``params`` (None thresholds shown as the descriptor's ``defaults``) without emitting."""
        shown = params.resolved(defaults or {})
        self._updating = True
        try:
            i = self.method.findData(shown.method)
            self.method.setCurrentIndex(max(i, 0))
            for name in ("node_sim_th", "loop_sim_th"):
                value = getattr(shown, name)
                if value is not None:
                    getattr(self, name).setValue(float(value))
            self.window_size.setValue(int(shown.window_size))
            self.count_th.setValue(int(shown.count_th))
            self.neighbor_node_num.setValue(int(shown.neighbor_node_num))
            self.long_runs.setChecked(bool(shown.long_runs))
        finally:
            self._updating = False
        self._params = params
        self._enable_for_method()

    def set_describe(self, descriptor: str, interval: float) -> None:
        self._updating = True
        try:
            i = self.descriptor.findText(descriptor)
            if i < 0:
                self.descriptor.addItem(descriptor)
                i = self.descriptor.count() - 1
            self.descriptor.setCurrentIndex(i)
            self.interval.setValue(float(interval))
        finally:
            self._updating = False

    def descriptor_name(self) -> str:
        return self.descriptor.currentText()

    def interval_value(self) -> float:
        return float(self.interval.value())

    # -- edits -------------------------------------------------------------------------
    def _edited(self, field: str) -> None:
        if self._updating:
            return
        if field == "method":
            value = self.method.currentData()
        elif field == "long_runs":
            value = self.long_runs.isChecked()
        else:
            value = getattr(self, field).value()
        self._params = replace(self._params, **{field: value})
        self._enable_for_method()
        self.paramsEdited.emit(field, self._params)

    def _describe_changed(self) -> None:
        if not self._updating:
            self.describeEdited.emit()

    def _enable_for_method(self) -> None:
        """Only the parameters the chosen method reads can be edited."""
        used = PARAMS_USED.get(self.method.currentData(), set(PARAMS_USED["ours"]))
        for name in set().union(*PARAMS_USED.values()):
            getattr(self, name).setEnabled(name in used)
        self.calibrate_button.setEnabled("loop_sim_th" in used)


# Which map parameters each method reads (engine/loops.py, engine/loops_verified.py):
# "verified" calibrates its own thresholds and has no window.
PARAMS_USED = {
    "simple": {"node_sim_th", "loop_sim_th"},
    "shift-simple": {"node_sim_th", "loop_sim_th"},
    "ours": {"node_sim_th", "loop_sim_th", "window_size", "count_th", "neighbor_node_num"},
    "verified": {"node_sim_th", "neighbor_node_num"},
    "verified-rules": {"node_sim_th", "neighbor_node_num", "long_runs"},
}


def _double(lo: float, hi: float, step: float, tip: str) -> QDoubleSpinBox:
    w = QDoubleSpinBox()
    w.setRange(lo, hi)
    w.setSingleStep(step)
    w.setDecimals(3)
    w.setToolTip(tip)
    w.setKeyboardTracking(False)  # apply when typing is done, not at every digit
    return w


def _int(lo: int, hi: int, tip: str) -> QSpinBox:
    w = QSpinBox()
    w.setRange(lo, hi)
    w.setToolTip(tip)
    w.setKeyboardTracking(False)
    return w
