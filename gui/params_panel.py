"""Parameters panel: descriptor settings (need a new describe) and map parameters (instant).

Map parameter edits emit ``paramsEdited(field, MapParams)``; the window rebuilds
the map from the cached descriptors at once. Descriptor and interval edits emit
``describeEdited`` and are applied by the Run button (a new describe, cached).
The paper's parameters have hand-made widgets; every other parameter of the typed
table (``engine.params.PARAMETERS``) gets a widget generated from its entry, so a
threshold added to the table is editable here without touching this module.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import replace
from typing import Optional

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QValidator
from PySide6.QtWidgets import (QAbstractSpinBox, QApplication, QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout,
                               QFrame, QGroupBox, QHBoxLayout, QPushButton, QScrollArea, QSpinBox, QVBoxLayout,
                               QWidget)

from engine import params as params_module
from engine.descriptors.efficientnet import PHOTOMETRIC
from engine.params import MapParams, Parameter

# The photometric choices the panel offers: None leaves it to the method.
PHOTOMETRIC_ITEMS = (("As the method asks", None),) + tuple((v.capitalize(), v) for v in PHOTOMETRIC)


def photometric_applies(descriptor: str) -> bool:
    """Whether ``descriptor`` has the ``photometric`` option (engine.validate's options table)."""
    from engine.validate import ALLOWED_OPTIONS

    return "photometric" in ALLOWED_OPTIONS.get(descriptor, {})


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
    DEFAULTS_FIELD = "defaults"          # the field name of the group's "Defaults" edit (one undo step)

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
        # effnet-vlad's photometric option: by default what the method asks for
        # (engine.params.METHOD_DESCRIBE_OPTIONS: verified standardises, the paper's methods do not).
        self.photometric = QComboBox()
        for text, value in PHOTOMETRIC_ITEMS:
            self.photometric.addItem(text, value)
        self.photometric.setToolTip("effnet-vlad: give the network each frame with its colour channels at zero mean "
                                    "and unit spread, so that exposure and white balance changes between visits "
                                    "count less. 'As the method asks': verified does, the paper's methods do not "
                                    "(their thresholds were calibrated without it). Applied by Run.")
        self.run_button = QPushButton("Run")
        self.run_button.setToolTip("Describe the recording with these settings and build the map (F5)")
        self.run_button.clicked.connect(self.runRequested)
        self.descriptor.currentIndexChanged.connect(lambda _: self._describe_changed())
        self.interval.valueChanged.connect(lambda _: self._describe_changed())
        self.photometric.currentIndexChanged.connect(lambda _: self._describe_changed())
        self.descriptor.currentIndexChanged.connect(lambda _: self._enable_photometric())

        self.method = QComboBox()
        for m in params_module.METHODS:  # read at run time: methods may be added
            self.method.addItem(m, m)
            self.method.setItemData(self.method.count() - 1, METHOD_TIPS.get(m, m), 3)
        self.method.setToolTip("Loop detection method (Table I of the paper)")
        self.node_sim_th = _double(0.0, 1.0, 0.01, "Similarity above which a frame is merged into the current node "
                                                   "(verified: calibrated from the recording unless you change it; "
                                                   "'auto' until the map is built)", threshold=True)
        self.loop_sim_th = _double(-1.0, 1.0, 0.01, "Similarity above which two nodes may be the same place",
                                   threshold=True)
        self.window_size = _int(1, 100, "Nodes per sliding window of the spatial consistency check")
        self.count_th = _int(0, 100, "A window is a candidate when more than this many of its nodes match")
        self.neighbor_node_num = _int(0, 1000, "Temporal neighbours of the query that windows must avoid")
        self.calibrate_button = QPushButton("Thresholds from recording")
        self.calibrate_button.setToolTip("simple / shift-simple / ours: set the node and loop thresholds "
                                         "from this recording's own similarities (undoable)")
        self.calibrate_button.clicked.connect(self.calibrateRequested)

        self.method.currentIndexChanged.connect(lambda _: self._edited("method"))
        for name in ("node_sim_th", "loop_sim_th", "window_size", "count_th", "neighbor_node_num"):
            getattr(self, name).valueChanged.connect(lambda _, n=name: self._edited(n))

        describe_box = QGroupBox("Descriptors")
        form = QFormLayout(describe_box)
        form.addRow("Descriptor", self.descriptor)
        form.addRow("Interval", self.interval)
        form.addRow("Photometric", self.photometric)
        self._describe_form = form
        row = QHBoxLayout()
        row.addStretch(1)
        row.addWidget(self.run_button)
        form.addRow(row)
        map_box = QGroupBox("Map (applied at once)")
        self._map_form = form = QFormLayout(map_box)
        form.addRow("Method", self.method)
        form.addRow("Node similarity", self.node_sim_th)
        form.addRow("Loop similarity", self.loop_sim_th)
        form.addRow("Window size", self.window_size)
        form.addRow("Count threshold", self.count_th)
        form.addRow("Neighbour nodes", self.neighbor_node_num)
        form.addRow("", self.calibrate_button)
        self._build_evidence()

        # One scroll area for the whole panel: with the generated rows it is taller than a
        # 720-px screen leaves the dock, and the window must still fit there.
        inner = QWidget()
        layout = QVBoxLayout(inner)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(describe_box)
        layout.addWidget(map_box)
        layout.addWidget(self.evidence_box)
        layout.addStretch(1)
        self.scroll = QScrollArea()
        self.scroll.setWidget(inner)
        self.scroll.setWidgetResizable(True)
        self.scroll.setFrameShape(QFrame.NoFrame)
        self.scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
        # Never narrower than the rows (no clipped spin boxes), scroll bar included.
        bar = self.scroll.verticalScrollBar().sizeHint().width()
        self.scroll.setMinimumWidth(inner.minimumSizeHint().width() + bar)
        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        outer.addWidget(self.scroll)
        for w in inner.findChildren(QAbstractSpinBox) + inner.findChildren(QComboBox):
            w.setFocusPolicy(Qt.StrongFocus)   # a wheel does not focus it...
            w.installEventFilter(self)         # ...and scrolls the panel (eventFilter)
        self.set_params(MapParams(), {"node_sim_th": 0.8, "loop_sim_th": 0.55})
        self._enable_photometric()

    def _build_evidence(self) -> None:
        """A generated row for each table parameter without a hand-made widget (``verified``'s
        thresholds), and a button back to the table's defaults."""
        self.generated: dict[str, Parameter] = {p.name: p for p in params_module.PARAMETERS
                                                if p.name not in HAND_MADE and p.type in (bool, int, float)}
        self.evidence = {name: _widget_for(p) for name, p in self.generated.items()}
        for name, w in self.evidence.items():
            signal = w.toggled if isinstance(w, QCheckBox) else w.valueChanged
            signal.connect(lambda _, n=name: self._edited(n))
        self.defaults_button = QPushButton("Defaults")
        self.defaults_button.setToolTip("This group's values back to the defaults of engine/params.py "
                                        "(one undo step)")
        self.defaults_button.clicked.connect(self.restore_defaults)
        self.evidence_box = QGroupBox("Loop evidence")
        self._evidence_form = form = QFormLayout(self.evidence_box)
        for name, w in self.evidence.items():
            form.addRow(name, w)   # the table's name: the CLI option, the GraphML key, the help's words
        row = QHBoxLayout()
        row.addStretch(1)
        row.addWidget(self.defaults_button)
        form.addRow(row)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """A wheel over a field not being edited scrolls the panel: it must not change a
        threshold (and re-map) in passing."""
        if event.type() == QEvent.Wheel and not watched.hasFocus():
            QApplication.sendEvent(self.scroll.verticalScrollBar(), event)
            return True
        return super().eventFilter(watched, event)

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
                box = getattr(self, name)
                if value is not None:
                    box.setValue(float(value))
                box.set_unknown(value is None)   # the value the map will use is not known yet
            self.window_size.setValue(int(shown.window_size))
            self.count_th.setValue(int(shown.count_th))
            self.neighbor_node_num.setValue(int(shown.neighbor_node_num))
            self._show_evidence(shown)
        finally:
            self._updating = False
        self._params = params
        self._enable_for_method()

    def _show_evidence(self, params: MapParams) -> None:
        for name, w in self.evidence.items():
            value = getattr(params, name)
            if value is None:
                continue
            if isinstance(w, QCheckBox):
                w.setChecked(bool(value))
            else:
                w.setValue(value)

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

    def photometric_choice(self) -> Optional[str]:
        """effnet-vlad's ``photometric`` as chosen here; None: what the method asks for."""
        return self.photometric.currentData()

    def set_photometric(self, value: Optional[str]) -> None:
        """Show ``value`` (None: "as the method asks") without emitting."""
        self._updating = True
        try:
            self.photometric.setCurrentIndex(max(self.photometric.findData(value), 0))
        finally:
            self._updating = False

    def _enable_photometric(self) -> None:
        """The row only where the descriptor has the option (effnet-vlad)."""
        self._describe_form.setRowVisible(self.photometric, photometric_applies(self.descriptor_name()))

    def interval_value(self) -> float:
        return float(self.interval.value())

    # -- edits -------------------------------------------------------------------------
    def _edited(self, field: str) -> None:
        if self._updating:
            return
        if field == "method":
            value = self.method.currentData()
        else:
            w = self.evidence[field] if field in self.evidence else getattr(self, field)
            value = w.isChecked() if isinstance(w, QCheckBox) else w.value()
        self._params = replace(self._params, **{field: value})
        self._enable_for_method()
        self.paramsEdited.emit(field, self._params)

    def restore_defaults(self) -> None:
        """The table's defaults for every generated row the method reads, as one edit (one undo step)."""
        new = replace(self._params, **{n: p.default for n, p in self._read_generated().items()})
        if new == self._params:
            return
        self._updating = True
        try:
            self._show_evidence(new)
        finally:
            self._updating = False
        self._params = new
        self._enable_for_method()
        self.paramsEdited.emit(self.DEFAULTS_FIELD, new)

    def _read_generated(self) -> dict[str, Parameter]:
        method = self.method.currentData()
        return {n: p for n, p in self.generated.items() if method in p.methods}

    def _describe_changed(self) -> None:
        if not self._updating:
            self.describeEdited.emit()

    def _enable_for_method(self) -> None:
        """Only the parameters the chosen method reads are shown (and enabled): on a 720-px
        screen the rows of the others would push ``verified``'s thresholds out of sight."""
        used = PARAMS_USED.get(self.method.currentData(), set(PARAMS_USED["ours"]))
        for name in set().union(*PARAMS_USED.values()):
            getattr(self, name).setEnabled(name in used)
            self._map_form.setRowVisible(getattr(self, name), name in used)
        self.calibrate_button.setEnabled("loop_sim_th" in used)
        self._map_form.setRowVisible(self.calibrate_button, "loop_sim_th" in used)
        read = self._read_generated()
        for name, w in self.evidence.items():
            w.setEnabled(name in read)
            self._evidence_form.setRowVisible(w, name in read)
        self.evidence_box.setVisible(bool(read))
        self.evidence_box.setTitle(f"Loop evidence ({self.method.currentData()})")
        self.defaults_button.setEnabled(any(getattr(self._params, n) != p.default for n, p in read.items()))


# Which map parameters each method reads (engine/loops.py, engine/loops_verified.py):
# "verified" calibrates its own thresholds and has no window.
PARAMS_USED = {
    "simple": {"node_sim_th", "loop_sim_th"},
    "shift-simple": {"node_sim_th", "loop_sim_th"},
    "ours": {"node_sim_th", "loop_sim_th", "window_size", "count_th", "neighbor_node_num"},
    "verified": {"node_sim_th", "neighbor_node_num"},
}
# Parameters with a widget made by hand above; the panel generates one for every other.
HAND_MADE = {"method"}.union(*PARAMS_USED.values())
# Spin box bounds where the table declares none, or one too large to show (its digits set the box's width).
SPIN_LIMIT = 1e6


class ThresholdBox(QDoubleSpinBox):
    """A threshold whose value may not be known yet: then it reads "auto" (issue 43, defect 6).

    An unset threshold stands for the value the map is built with, which ``verified``
    calibrates from the recording: until that map is there, no number is shown (a
    number shown during a run that changes after it is a wrong number). Typing or
    stepping makes it a value of the user's again.
    """

    AUTO = "auto"

    def __init__(self) -> None:
        super().__init__()
        self.unknown = False
        self.lineEdit().textEdited.connect(self._typed)

    def set_unknown(self, on: bool) -> None:
        if on != self.unknown:
            self.unknown = on
            self.lineEdit().setText(self.textFromValue(self.value()))

    def _typed(self, _text: str) -> None:
        self.unknown = False

    def textFromValue(self, value: float) -> str:
        return self.AUTO if self.unknown else super().textFromValue(value)

    def valueFromText(self, text: str) -> float:
        return self.value() if text == self.AUTO else super().valueFromText(text)

    def validate(self, text: str, pos: int):
        if text == self.AUTO:
            return QValidator.Acceptable, text, pos
        return super().validate(text, pos)

    def stepBy(self, steps: int) -> None:
        self.unknown = False
        super().stepBy(steps)


def _double(lo: float, hi: float, step: float, tip: str, threshold: bool = False) -> QDoubleSpinBox:
    w = ThresholdBox() if threshold else QDoubleSpinBox()
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


def spin_range(p: Parameter) -> tuple[float, float]:
    """The table's range, or +-``SPIN_LIMIT`` for a missing or huge bound."""
    lo = p.minimum if p.minimum is not None and abs(p.minimum) <= SPIN_LIMIT else -SPIN_LIMIT
    hi = p.maximum if p.maximum is not None and abs(p.maximum) <= SPIN_LIMIT else SPIN_LIMIT
    return lo, hi


def float_step(p: Parameter, lo: float, hi: float) -> float:
    """A tenth of the default's order of magnitude (0.6 -> 0.01, 3.5 -> 0.1, 35 -> 1), within the
    range: an arrow click nudges the value, it does not jump across what matters."""
    scale = min(abs(float(p.default or 0.0)) or hi - lo, hi - lo)
    return 10.0 ** (math.floor(math.log10(scale)) - 1) if scale > 0 else 0.1


def tooltip(p: Parameter) -> str:
    """What it does and where its number came from, wrapped: Qt shows a plain tooltip on one line."""
    text = f"{p.help}\nWhere the number came from: {p.origin} (default {p.default})"
    return "\n".join(textwrap.fill(line, 90) for line in text.split("\n"))


def _widget_for(p: Parameter) -> QWidget:
    """A check box, spin box or double spin box for one table entry, showing its default."""
    if p.type is bool:
        w = QCheckBox()
        w.setChecked(bool(p.default))
    elif p.type is int:
        lo, hi = spin_range(p)
        w = _int(int(math.ceil(lo)), int(math.floor(hi)), "")
    else:
        lo, hi = spin_range(p)
        step = float_step(p, lo, hi)
        w = _double(lo, hi, step, "")
        decimals = max(2, 1 - math.floor(math.log10(step)))
        while decimals < 6 and any(v is not None and round(float(v), decimals) != v for v in (p.default, lo, hi)):
            decimals += 1   # the default and the range shown exactly (a minimum of 0.001 is not 0)
        w.setDecimals(decimals)
        w.setRange(lo, hi)   # again: the range is rounded to the decimals in force when it is set
    if p.type is not bool and p.default is not None:
        w.setValue(p.default)
    w.setToolTip(tooltip(p))
    return w
