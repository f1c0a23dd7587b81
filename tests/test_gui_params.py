"""The parameters panel offers only what the chosen method reads."""

import pytest


@pytest.mark.parametrize("method, enabled, disabled", [
    ("ours", {"loop_sim_th", "window_size", "count_th", "neighbor_node_num"}, {"long_runs"}),
    ("simple", {"loop_sim_th"}, {"window_size", "count_th", "neighbor_node_num", "long_runs"}),
    ("verified", {"neighbor_node_num"}, {"loop_sim_th", "window_size", "count_th", "long_runs"}),
    ("verified-rules", {"neighbor_node_num", "long_runs"}, {"loop_sim_th", "window_size", "count_th"}),
])
def test_parameters_panel_enables_what_the_method_reads(qtbot, method, enabled, disabled):
    from gui.params_panel import ParamsPanel

    panel = ParamsPanel()
    qtbot.addWidget(panel)
    panel.method.setCurrentIndex(panel.method.findData(method))
    assert all(getattr(panel, n).isEnabled() for n in enabled)
    assert not any(getattr(panel, n).isEnabled() for n in disabled)


def test_long_runs_checkbox_edits_the_parameter(qtbot):
    from gui.params_panel import ParamsPanel

    panel = ParamsPanel()
    qtbot.addWidget(panel)
    assert panel.long_runs.isChecked() and panel.params().long_runs
    with qtbot.waitSignal(panel.paramsEdited) as sig:
        panel.long_runs.setChecked(False)
    assert sig.args[0] == "long_runs" and sig.args[1].long_runs is False
    assert panel.params().long_runs is False
