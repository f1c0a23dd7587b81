"""The review queue in the real window, and the curation defects of issue 14.

Maps are made by hand (nodes, loop arcs with evidence) and shown in a real
MainWindow on the offscreen platform; where a run matters, a descriptors file of a
route that passes the same places twice is opened and mapped by the real engine.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QSettings, Qt  # noqa: E402
from PySide6.QtWidgets import QApplication, QMessageBox  # noqa: E402

from gui.main_window import MainWindow  # noqa: E402
from test_app_model import candidates, make_map  # noqa: E402


@pytest.fixture
def window(qtbot, tmp_path, monkeypatch):
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.No)
    monkeypatch.setattr(QMessageBox, "warning", lambda *a, **k: QMessageBox.Ok)
    monkeypatch.setattr(QMessageBox, "critical", lambda *a, **k: QMessageBox.Ok)
    w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), cache_root=str(tmp_path))
    qtbot.addWidget(w)
    w.resize(1280, 720)
    w.show()
    w.activateWindow()
    yield w
    w.undo_stack.setClean()
    w._extra_dirty = False
    w.shutdown()


def show(w: MainWindow, loops: list[dict], nodes: int = 60) -> None:
    w.doc.replace_map(make_map(loops, nodes))


def statuses(w: MainWindow) -> dict:
    return {r.key: r.status for r in w.doc.loop_rows()}


def few(n: int = 4) -> list[dict]:
    return [dict(a=i, b=i + 30, status="candidate", score=0.9 - 0.1 * i) for i in range(n)]


def test_300_candidates_take_a_handful_of_keys_and_undo_in_two(qtbot, window):
    w = window
    loops = candidates(good=250, bad=50)
    show(w, loops, nodes=700)
    truth = {(10 * lp["a"], 10 * lp["b"]): lp["truth"] for lp in loops}
    view = w.loop_table.view
    ranked = w.loop_table.visible_keys()                 # the table opens in evidence order
    assert [truth[k] for k in ranked[:250]] == ["good"] * 250

    view.setFocus()
    w.loop_table.select_key(ranked[249])                 # 1: click the weakest good loop
    qtbot.keyClick(view, Qt.Key_R, Qt.ShiftModifier)     # 2: reject everything ranked below it
    w.loop_table.filter.setCurrentIndex(w.loop_table.filter.findText("Undecided (candidate + auto)"))  # 3
    qtbot.keyClick(view, Qt.Key_A, Qt.ControlModifier)   # 4: select all shown
    qtbot.keyClick(view, Qt.Key_C)                       # 5: confirm them
    assert all(statuses(w)[k] == ("confirmed" if t == "good" else "rejected") for k, t in truth.items())
    assert w.undo_stack.count() == 2

    qtbot.keyClick(view, Qt.Key_Z, Qt.ControlModifier)
    qtbot.keyClick(view, Qt.Key_Z, Qt.ControlModifier)
    assert set(statuses(w).values()) == {"candidate"}
    assert "300 undecided" in w.summary_label.text()


def test_repeated_reject_on_the_last_row_rejects_only_that_loop(qtbot, window):
    """Defect 1: R R on the last loop wrapped the selection and rejected another loop."""
    w = window
    show(w, few())
    order = w.loop_table.visible_keys()
    w.loop_table.select_key(order[-1])
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    assert [statuses(w)[k] for k in order] == ["candidate"] * 3 + ["rejected"]
    assert w.loop_table.selected_key() == order[-1]


def test_next_undecided_key_and_j_k_wrap_both_ways(qtbot, window):
    """Defect 10 (first half): K did not wrap backwards while J did."""
    w = window
    show(w, few())
    order = w.loop_table.visible_keys()
    view = w.loop_table.view
    w.loop_table.select_key(order[0])
    qtbot.keyClick(view, Qt.Key_K)
    assert w.loop_table.selected_key() == order[-1]
    qtbot.keyClick(view, Qt.Key_J)
    assert w.loop_table.selected_key() == order[0]
    qtbot.keyClick(view, Qt.Key_C)                       # confirms order[0], moves to order[1]
    qtbot.keyClick(view, Qt.Key_C)                       # confirms order[1]
    w.loop_table.select_key(order[0])
    qtbot.keyClick(view, Qt.Key_F)                       # next undecided: skips the two confirmed
    assert w.loop_table.selected_key() == order[2]
    assert statuses(w)[order[2]] == "candidate"


def test_tab_leaves_the_table_and_reaches_the_frame_viewer(qtbot, window):
    """Defect 6: Tab never left the loop table; the frame viewer showed no focus."""
    w = window
    show(w, few())
    view = w.loop_table.view
    view.setFocus()
    qtbot.waitUntil(view.hasFocus)
    qtbot.keyClick(view, Qt.Key_Tab)
    assert QApplication.focusWidget() is not view
    for _ in range(100):   # every focusable widget of the window at most
        focused = QApplication.focusWidget()
        if focused is w.frame_viewer or w.frame_viewer.isAncestorOf(focused):
            break
        qtbot.keyClick(focused, Qt.Key_Tab)
    assert QApplication.focusWidget() is w.frame_viewer
    assert w.frame_viewer.property("keyFocus") is True
    view.setFocus()
    assert w.frame_viewer.property("keyFocus") is False


def test_ctrl_z_in_the_place_name_field_undoes_the_applied_name(qtbot, window):
    """Defect 7: Ctrl+Z in the field undid the text only; the name stayed applied."""
    w = window
    show(w, few())
    w.node_panel.show_node(4)
    frame = int(w.doc.node_frames()[4])
    field = w.node_panel.name
    field.setFocus()
    qtbot.keyClicks(field, "kitchen")
    qtbot.keyClick(field, Qt.Key_Return)
    assert w.doc.label_of_frame(frame) == "kitchen"
    qtbot.keyClick(field, Qt.Key_Z, Qt.ControlModifier)
    assert w.doc.label_of_frame(frame) == ""
    assert field.text() == ""
    qtbot.keyClicks(field, "hall")                       # an edit not applied yet: the field's own undo
    qtbot.keyClick(field, Qt.Key_Z, Qt.ControlModifier)
    assert w.doc.label_of_frame(frame) == ""


def test_undefined_metrics_read_na_not_zero(qtbot, window):
    """Defect 14: with no detections, precision showed 0.0 % instead of n/a."""
    from engine.poses import Poses

    w = window
    show(w, [], nodes=20)
    t = np.arange(20, dtype=np.float64)
    w.doc.set_poses(Poses(t, t, np.zeros(20)), None)     # a straight walk: no place is seen twice
    assert w.doc.evaluation is not None
    assert "n/a" in w.eval_panel.values["precision"].text()
    assert "n/a" in w.eval_panel.values["recall"].text()
    assert "%" in w.eval_panel.values["accuracy"].text()


def _route_descriptors(path: Path, n: int = 240, d: int = 64) -> Path:
    """Descriptors of a route driven twice (the second lap sees the first lap's places)."""
    from engine.descriptors.base import Descriptors

    rng = np.random.default_rng(0)
    places = rng.normal(size=(n // 2, d)).cumsum(axis=0)
    vectors = np.concatenate([places, places]) + rng.normal(scale=0.3, size=(n, d))
    vectors /= np.linalg.norm(vectors, axis=1, keepdims=True)
    Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                shifts=np.zeros(n, np.int64), vectors=vectors.astype(np.float32),
                meta={"descriptor": "effnet-vlad", "interval": 1.0, "shift": True}).save(path)
    return path


def test_remap_and_similarity_run_off_the_ui_thread(qtbot, window, tmp_path, monkeypatch):
    """Defect 11: build_map and the similarity matrix ran on the UI thread."""
    import engine.loops
    import engine.pipeline

    w = window
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("ours"))
    with qtbot.waitSignal(w.mapReady, timeout=60_000):
        assert w.open_path(str(_route_descriptors(tmp_path / "route.npz")))
    threads = {}
    real_build, real_sim = engine.pipeline.build_map, engine.loops.similarity_matrix

    def build_map(*args, **kwargs):
        threads["build_map"] = threading.get_ident()
        return real_build(*args, **kwargs)

    def similarity_matrix(*args, **kwargs):
        threads["similarity"] = threading.get_ident()
        return real_sim(*args, **kwargs)

    monkeypatch.setattr(engine.pipeline, "build_map", build_map)
    monkeypatch.setattr(engine.loops, "similarity_matrix", similarity_matrix)
    before = w.doc.topomap
    with qtbot.waitSignal(w.mapReady, timeout=30_000):
        w.params_panel.neighbor_node_num.setValue(w.params_panel.neighbor_node_num.value() + 1)
    assert w.doc.topomap is not before
    w.tabs.setCurrentWidget(w.similarity_view)
    qtbot.waitUntil(w.doc.similarity_ready, timeout=30_000)
    ui = threading.get_ident()
    assert threads["build_map"] != ui and threads["similarity"] != ui


def test_newest_parameter_change_wins(qtbot, window, tmp_path):
    w = window
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("ours"))
    with qtbot.waitSignal(w.mapReady, timeout=60_000):
        assert w.open_path(str(_route_descriptors(tmp_path / "route.npz")))
    start = w.params_panel.neighbor_node_num.value()
    for step in (1, 2, 3):                               # three quick changes: one map, the last one
        w.params_panel.neighbor_node_num.setValue(start + step)
    assert w.remapper.wait(30_000)
    assert w.doc.topomap.meta["neighbor_node_num"] == start + 3


def test_opening_another_recording_clears_the_pair_and_the_graph_selection(qtbot, window, tmp_path):
    """Defect 5: the previous pair captions and graph selection stayed on screen."""
    from engine.synth import make_recording, write_recording

    w = window
    show(w, few())
    w.loop_table.select_key(w.loop_table.visible_keys()[0])
    assert w.pair_view.key is not None and w.graph_view.selected_key is not None
    rec = make_recording(route="loop", look="indoor", width=128, height=64, fps=2.0, max_frames=12)
    video = write_recording(rec, tmp_path, formats=("video",))["video"]
    assert w.open_path(str(video), run=False)
    assert w.pair_view.key is None and w.graph_view.selected_key is None
    assert w.pair_view.caption.text() == "" and w.pair_view.evidence.text() == ""   # no old captions


def test_menus_and_help_come_from_the_key_table_with_the_settings_overrides(qtbot, tmp_path, monkeypatch):
    import json

    from PySide6.QtGui import QKeySequence

    from gui.model.keys import SHORTCUTS
    from gui.shortcuts_dialog import ShortcutsDialog

    config = tmp_path / "config"
    (config / "panotopo").mkdir(parents=True)
    (config / "panotopo" / "settings.json").write_text(json.dumps(
        {"shortcuts": {"confirm": ["Return"], "next_undecided": "X", "no_such_action": "Q"}}))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(config))
    w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), cache_root=str(tmp_path))
    qtbot.addWidget(w)
    try:
        for entry in SHORTCUTS:
            if entry.fixed:
                continue
            action = w.action_of_key[entry.action]
            expected = {"confirm": ["Return"], "next_undecided": ["X"]}.get(entry.action, list(entry.keys))
            assert action.shortcuts() == [QKeySequence(k) for k in expected], entry.action
        assert "no_such_action" in w.statusBar().currentMessage()
        dialog = ShortcutsDialog(w.shortcuts, w)
        table = dialog.layout().itemAt(0).widget()
        shown = {table.item(r, 2).text(): table.item(r, 1).text() for r in range(table.rowCount())}
        assert shown["Confirm the selected loops (same place)"] == "Return"
        assert len(shown) == len(SHORTCUTS)
    finally:
        w.shutdown()
