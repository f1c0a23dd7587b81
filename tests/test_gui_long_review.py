"""The app for a long review (issue 43): the review queue, the pair view after a reopen,
the manual-loop dialog, place names and parameters per recording, in the real window."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402
from PySide6.QtWidgets import QMessageBox, QTableWidget  # noqa: E402

from engine.session_fields import LABEL_MAX  # noqa: E402
from gui_maps import window_maker, boxes  # noqa: E402,F401  (a fixture)
from test_app_model import make_map  # noqa: E402
from test_gui_review import _route_descriptors  # noqa: E402


@pytest.fixture
def make_window(qtbot, tmp_path, boxes):
    yield from window_maker(qtbot, tmp_path, size=(1280, 720))


def open_and_run(qtbot, w, path) -> None:
    with qtbot.waitSignal(w.mapReady, timeout=60_000):
        assert w.open_path(str(path))


def test_reopening_a_recording_with_a_session_fills_the_pair_view(qtbot, make_window, tmp_path):
    """Defect 5: File > Open highlighted the restored row, but the pair view said "Select a
    loop candidate" and Confirm/Reject were disabled."""
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("ours"))
    open_and_run(qtbot, w, npz)
    key = w.loop_table.visible_keys()[1]
    w.loop_table.select_key(key)
    assert w.save_session()
    open_and_run(qtbot, w, npz)          # File > Open of the same recording
    qtbot.wait(20)
    assert w.loop_table.selected_key() == key
    assert w.pair_view.key == key
    assert w.pair_view.confirm_button.isEnabled() and w.pair_view.reject_button.isEnabled()


def test_after_a_bulk_decision_the_current_row_stays_where_the_user_was(qtbot, make_window):
    """Defect 8: select rows 1-7, C, Down, Up landed on row 1, not 7."""
    w = make_window()
    w.doc.replace_map(make_map([dict(a=i, b=i + 30, status="candidate", score=0.9 - 0.05 * i) for i in range(12)], 60))
    view = w.loop_table.view
    w.activateWindow()
    view.setFocus()
    w.loop_table.select_key(w.loop_table.visible_keys()[0])
    for _ in range(6):
        qtbot.keyClick(view, Qt.Key_Down, Qt.ShiftModifier)
    chosen = w.loop_table.selected_keys()
    assert len(chosen) == 7
    w.action_of_key["confirm"].trigger()        # C
    assert {r.key: r.status for r in w.doc.loop_rows() if r.key in chosen} == dict.fromkeys(chosen, "confirmed")
    assert view.currentIndex().row() == 6
    qtbot.keyClick(view, Qt.Key_Down)
    qtbot.keyClick(view, Qt.Key_Up)
    assert view.currentIndex().row() == 6


def test_a_place_name_is_limited_where_it_is_typed(qtbot, make_window, boxes, tmp_path):
    """Defect 16: a name over 1,000 characters was saved, and the session then refused to load."""
    from engine.session import Session

    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    assert w.node_panel.name.maxLength() == LABEL_MAX
    w.node_panel.show_node(3)
    w.node_panel.name.setFocus()
    w.node_panel.name.setText("x" * (LABEL_MAX + 200))
    qtbot.keyClick(w.node_panel.name, Qt.Key_Return)
    frame = int(w.doc.node_frames()[3])
    assert len(w.doc.label_of_frame(frame)) <= LABEL_MAX
    w.set_label(frame, "y" * (LABEL_MAX + 1))     # any other way in is refused, with a reason
    assert boxes and "at most" in boxes[-1][1]
    assert w.save_session()
    Session.load(w.doc.session_path)


def test_parameters_do_not_carry_over_to_the_next_recording(qtbot, make_window, tmp_path, monkeypatch):
    """Defect 3: retrieval_k 32 and auto_z 5.5 set on one recording were used on the next,
    even after Discard."""
    from dataclasses import replace

    first = _route_descriptors(tmp_path / "first.npz")
    second = _route_descriptors(tmp_path / "second.npz")
    w = make_window()
    start = w.doc.params
    open_and_run(qtbot, w, first)
    changed = replace(w.doc.params, retrieval_k=32, auto_z=5.5)
    w.runs._params_edited("retrieval_k", changed)
    assert w.doc.params.retrieval_k == 32
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.Discard)
    open_and_run(qtbot, w, second)
    assert w.doc.params == start
    assert w.params_panel.params() == start


def test_the_node_threshold_shows_no_number_the_run_will_contradict(qtbot, make_window, tmp_path):
    """Defect 6: the node-similarity field read 0.790 during a run and 0.725 after it."""
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("verified"))
    shown = []
    w.runner.started.connect(lambda: shown.append(w.params_panel.node_sim_th.text()))
    open_and_run(qtbot, w, npz)
    after = w.params_panel.node_sim_th.text()
    open_and_run(qtbot, w, npz)
    again = w.params_panel.node_sim_th.text()
    during = set(shown)
    assert after == again
    assert during <= {after, "auto"}, (during, after)


def test_the_graph_is_the_map_as_decided_and_is_redrawn_after_each_decision(qtbot, make_window):
    """Defect 2: without ground truth the layout used undecided candidates and was not redrawn."""
    w = make_window()
    n = 60
    w.doc.replace_map(make_map([dict(a=0, b=n - 1, status="candidate", score=0.9)], n))
    g = w.graph_view

    def gap() -> float:
        return float(np.hypot(g.x[0] - g.x[n - 1], g.y[0] - g.y[n - 1]))

    assert gap() > 0.5 * (n - 1), "an undecided candidate does not fold the drawing"
    w.loop_table.select_key(w.loop_table.visible_keys()[0])
    w.decide("confirmed")
    assert g.layout_worker.wait(30_000)
    assert gap() < 0.25 * (n - 1), "the confirmed loop is drawn as a loop"
    w.loop_table.select_key(w.loop_table.visible_keys()[0])
    w.decide("rejected")
    assert g.layout_worker.wait(30_000)
    assert gap() > 0.5 * (n - 1), "rejected: the loop is gone from the drawing"


def _queue(n_loops: int = 60, nodes: int = 400):
    return make_map([dict(a=i, b=i + 300, status="candidate", score=0.5, confidence=0.5 + i / 100, yaw=12.5)
                     for i in range(n_loops)], nodes)


@pytest.mark.parametrize("size", [(1920, 1040), (1500, 950)])
def test_the_queue_is_long_enough_to_review_in(qtbot, make_window, size):
    """Defect 7: 7-9 rows at 1500x950 and maximised at 1920x1080; Yaw took half the table's
    width; no confidence column although the queue is ranked by confidence."""
    from gui.loop_table import COLUMNS

    w = make_window(size)
    qtbot.waitExposed(w)
    qtbot.wait(50)        # the first split happens after the first layout
    w.doc.replace_map(_queue())
    qtbot.wait(20)
    view = w.loop_table.view
    rows = view.viewport().height() // view.rowHeight(0)
    assert rows >= 15, f"{rows} rows of the queue on screen at {size}"
    header = view.horizontalHeader()
    assert header.sectionSize(COLUMNS.index("Yaw°")) <= view.viewport().width() / 4
    conf = COLUMNS.index("Conf.")
    assert w.loop_table.proxy.index(0, conf).data() == "1.09", "the best-ranked loop's confidence is shown"


def test_one_key_takes_the_keyboard_to_the_queue_and_the_help_lists_it(qtbot, make_window):
    """Defect 7: about 40 Tabs from the parameter panel to the table, and no key to jump there."""
    from gui.model.keys import SHORTCUTS
    from gui.shortcuts_dialog import ShortcutsDialog

    w = make_window()
    w.doc.replace_map(_queue(10, 330))
    w.activateWindow()
    w.params_panel.node_sim_th.setFocus()
    qtbot.waitUntil(lambda: w.params_panel.node_sim_th.hasFocus(), timeout=2000)
    qtbot.keyClick(w.params_panel.node_sim_th, Qt.Key_L, Qt.ControlModifier)
    assert w.loop_table.view.hasFocus()
    assert w.loop_table.selected_key() is not None
    entry = next(s for s in SHORTCUTS if s.action == "focus_queue")
    dialog = ShortcutsDialog(w.shortcuts, w)
    qtbot.addWidget(dialog)
    table = dialog.findChild(QTableWidget)
    texts = {table.item(r, c).text() for r in range(table.rowCount()) for c in range(table.columnCount())}
    assert entry.text in texts and entry.shown in texts
