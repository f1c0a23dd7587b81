"""The parameters panel offers only what the chosen method reads."""

import pytest


@pytest.mark.parametrize("method, enabled, disabled", [
    ("ours", {"loop_sim_th", "window_size", "count_th", "neighbor_node_num"}, set()),
    ("simple", {"loop_sim_th"}, {"window_size", "count_th", "neighbor_node_num"}),
    ("verified", {"neighbor_node_num"}, {"loop_sim_th", "window_size", "count_th"}),
])
def test_parameters_panel_enables_what_the_method_reads(qtbot, method, enabled, disabled):
    from gui.params_panel import ParamsPanel

    panel = ParamsPanel()
    qtbot.addWidget(panel)
    panel.method.setCurrentIndex(panel.method.findData(method))
    assert all(getattr(panel, n).isEnabled() for n in enabled)
    assert not any(getattr(panel, n).isEnabled() for n in disabled)


# -- the rows generated from engine.params.PARAMETERS --------------------------------------

def _panel(qtbot, method="verified"):
    from gui.params_panel import ParamsPanel

    panel = ParamsPanel()
    qtbot.addWidget(panel)
    panel.method.setCurrentIndex(panel.method.findData(method))
    return panel


def _widget(panel, name):
    return panel.evidence[name] if name in panel.evidence else getattr(panel, name)


def _other_value(panel, name):
    """A value of ``name`` other than the one shown, inside its range."""
    from PySide6.QtWidgets import QCheckBox

    w = panel.evidence[name]
    if isinstance(w, QCheckBox):
        return not w.isChecked()
    up = w.value() + w.singleStep()
    value = up if up <= w.maximum() else w.value() - w.singleStep()
    return round(value, w.decimals()) if hasattr(w, "decimals") else value


def _changed(a, b):
    from dataclasses import fields

    return {f.name for f in fields(a) if getattr(a, f.name) != getattr(b, f.name)}


def test_every_parameter_verified_reads_is_an_editable_widget(qtbot):
    from engine.params import parameters_for

    panel = _panel(qtbot, "verified")
    read = [p.name for p in parameters_for("verified")]
    assert {"auto_inliers", "auto_geometry_z", "candidate_z", "place_radius"} <= set(read)
    for name in read:
        w = _widget(panel, name)
        assert w.isEnabled() and w.isVisibleTo(panel), name
    assert panel.evidence_box.isVisibleTo(panel) and "verified" in panel.evidence_box.title()


@pytest.mark.parametrize("method", ["simple", "shift-simple", "ours", "verified"])
def test_generated_rows_are_offered_only_to_the_methods_that_read_them(qtbot, method):
    from engine.params import BY_NAME

    panel = _panel(qtbot, method)
    assert panel.evidence, "the table has parameters without a hand-made widget"
    for name, w in panel.evidence.items():
        reads = method in BY_NAME[name].methods
        assert w.isEnabled() == reads and w.isVisibleTo(panel) == reads, name
    assert panel.evidence_box.isVisibleTo(panel) == any(method in BY_NAME[n].methods for n in panel.evidence)


def test_generated_widgets_follow_the_table(qtbot):
    from PySide6.QtWidgets import QCheckBox, QDoubleSpinBox, QSpinBox

    from engine.params import MapParams

    panel = _panel(qtbot)
    kinds = {int: QSpinBox, float: QDoubleSpinBox, bool: QCheckBox}
    for name, p in panel.generated.items():
        w = panel.evidence[name]
        assert type(w) is kinds[p.type], name
        assert (w.minimum(), w.maximum()) == (p.minimum, p.maximum), name   # the table's declared range
        assert not w.keyboardTracking(), name                               # applied when typing is done
        assert 0 < w.singleStep() <= (p.maximum - p.minimum) / 10, name
        assert w.value() == getattr(MapParams(), name) == p.default, name  # the default shown exactly
        tip = " ".join(w.toolTip().split())
        assert " ".join(p.help.split()) in tip, name
        assert f"Where the number came from: {' '.join(p.origin.split())} (default {p.default})" in tip, name
        assert max(len(line) for line in w.toolTip().splitlines()) <= 100, "a tooltip fits on the screen"


def test_a_missing_or_huge_bound_falls_back_to_a_showable_range(qtbot):
    from engine.params import Parameter
    from gui.params_panel import SPIN_LIMIT, _widget_for, spin_range

    assert spin_range(Parameter("x", float, 1.0, ("verified",), "h", "o")) == (-SPIN_LIMIT, SPIN_LIMIT)
    assert spin_range(Parameter("x", float, 1.0, ("verified",), "h", "o", 0.0, 1e300)) == (0.0, SPIN_LIMIT)
    w = _widget_for(Parameter("x", int, 3, ("verified",), "h", "o", None, 10**12))
    qtbot.addWidget(w)
    assert (w.minimum(), w.maximum()) == (-SPIN_LIMIT, SPIN_LIMIT) and w.value() == 3


def test_editing_a_generated_row_changes_that_field_and_nothing_else(qtbot):
    panel = _panel(qtbot)
    for name in panel.evidence:
        before = panel.params()
        with qtbot.waitSignal(panel.paramsEdited) as sig:
            panel.evidence[name].setValue(_other_value(panel, name))
        field, after = sig.args
        assert field == name and _changed(before, after) == {name}, name
        assert panel.params() == after


def test_set_params_shows_every_generated_field_without_emitting(qtbot):
    from dataclasses import replace

    panel = _panel(qtbot)
    wanted = replace(panel.params(), **{n: _other_value(panel, n) for n in panel.evidence})
    emitted = []
    panel.paramsEdited.connect(lambda *args: emitted.append(args))
    panel.set_params(wanted, {})
    assert not emitted
    assert panel.params() == wanted
    assert all(panel.evidence[n].value() == getattr(wanted, n) for n in panel.evidence)


def test_defaults_button_restores_the_table_in_one_edit(qtbot):
    from dataclasses import replace

    from PySide6.QtCore import Qt

    panel = _panel(qtbot)
    assert not panel.defaults_button.isEnabled()             # nothing to restore yet
    edited = replace(panel.params(), neighbor_node_num=7,
                     **{n: _other_value(panel, n) for n in panel.evidence})
    panel.set_params(edited, {})
    assert panel.defaults_button.isEnabled()
    emitted = []
    panel.paramsEdited.connect(lambda *args: emitted.append(args))
    qtbot.mouseClick(panel.defaults_button, Qt.LeftButton)
    assert len(emitted) == 1                                  # one edit: one undo step in the window
    field, after = emitted[0]
    assert field == panel.DEFAULTS_FIELD
    assert _changed(edited, after) == set(panel.evidence)      # the group's rows, nothing else
    assert all(getattr(after, n) == p.default == panel.evidence[n].value() for n, p in panel.generated.items())
    assert not panel.defaults_button.isEnabled()


def test_a_wheel_over_an_unfocused_threshold_scrolls_instead_of_editing(qtbot):
    from PySide6.QtCore import QPoint, QPointF, Qt
    from PySide6.QtGui import QWheelEvent
    from PySide6.QtWidgets import QApplication

    panel = _panel(qtbot)
    panel.resize(340, 300)
    panel.show()
    qtbot.waitExposed(panel)
    w = panel.evidence["auto_inliers"]
    shown = w.value()
    emitted = []
    panel.paramsEdited.connect(lambda *args: emitted.append(args))
    at = QPointF(w.rect().center())
    wheel = QWheelEvent(at, QPointF(w.mapToGlobal(at)), QPoint(), QPoint(0, -120), Qt.NoButton, Qt.NoModifier,
                        Qt.NoScrollPhase, False)
    QApplication.sendEvent(w, wheel)
    assert w.value() == shown and not emitted
    assert panel.scroll.verticalScrollBar().value() > 0
