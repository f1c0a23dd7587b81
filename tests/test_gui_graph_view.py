"""The graph view shows every loop, whatever its length, with toggles and counts per status."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402

from gui.graph_view import GraphView  # noqa: E402
from gui.style import STATUS_COLORS  # noqa: E402
from tests.gui_maps import colour_pixels, make_doc, square_walk  # noqa: E402

N = 20
# Node 19 is back at node 0's place; node 14 is back at node 4's place (3/4 of the way round).
POSITIONS = square_walk(N)
POSITIONS[14] = POSITIONS[4]


@pytest.fixture
def view(qtbot):
    def make(positions=POSITIONS, loops=((0, 19, "confirmed"), (4, 14, "manual"))):
        doc = make_doc(positions, loops, n=N)
        v = GraphView(doc)
        qtbot.addWidget(v)
        v.resize(640, 480)
        v.show()
        v.rebuild()
        qtbot.waitExposed(v)
        return v
    return make


def test_a_loop_between_two_nodes_at_one_place_is_visible(view):
    v = view()
    for key, status, node in (((0, 19), "confirmed", 19), ((4, 14), "manual", 14)):
        centre = v.plot.mapTo(v, v.node_screen_pos(node))
        pixels = colour_pixels(v, STATUS_COLORS[status], centre=(centre.x(), centre.y()), radius=60)
        assert pixels > 40, f"the {status} loop {key} joins nodes at one place and must still show"


def test_toggles_hide_a_status_and_count_it(view):
    v = view()
    centre = v.plot.mapTo(v, v.node_screen_pos(19))
    assert "(1)" in v.toggles["confirmed"].text() and "(1)" in v.toggles["manual"].text()
    assert "(0)" in v.toggles["rejected"].text()
    v.toggles["confirmed"].setChecked(False)
    assert colour_pixels(v, STATUS_COLORS["confirmed"], centre=(centre.x(), centre.y()), radius=60) == 0
    assert "(1)" in v.toggles["confirmed"].text(), "a hidden status is still counted"
    assert v.nearest_loop(*POSITIONS[19])[0] != (0, 19), "a hidden loop cannot be clicked"


def test_clicking_a_loop_curve_selects_it_and_the_selection_is_drawn(view, qtbot):
    v = view()
    apex = v.loop_apex((0, 19))
    assert apex is not None
    # The curve stands off its nodes by a visible distance (it is not a dot on the node).
    node = v.node_screen_pos(19)
    assert np.hypot(apex.x() - node.x(), apex.y() - node.y()) > 12
    with qtbot.waitSignal(v.loopClicked, timeout=2000) as got:
        qtbot.mouseClick(v.plot.viewport(), Qt.LeftButton, pos=apex)
    assert tuple(got.args[0]) == (0, 19)
    v.set_selected_loop((0, 19))
    xs, _ = v.selected_item.getData()
    assert xs is not None and np.isfinite(xs).sum() > 2, "the selected loop is highlighted along its curve"
    v.set_selected_loop(None)
    xs, _ = v.selected_item.getData()
    assert xs is None or len(xs) == 0


def test_new_candidate_status_has_its_own_toggle(view):
    v = view(loops=((0, 19, "candidate"), (4, 14, "auto")))
    assert "(1)" in v.toggles["candidate"].text() and "(1)" in v.toggles["auto"].text()
    centre = v.plot.mapTo(v, v.node_screen_pos(19))
    assert colour_pixels(v, STATUS_COLORS["candidate"], tol=30, centre=(centre.x(), centre.y()), radius=60) > 20
