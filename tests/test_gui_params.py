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
