"""Decisions written through to the journal (engine.journal) by the real window.

Every decision is on disk when the key is released; a window that dies without saving
loses nothing; a second window is told the recording is open elsewhere; a save
compacts the journal, a discard empties it.
"""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QSettings, Qt  # noqa: E402
from PySide6.QtWidgets import QMessageBox  # noqa: E402

from gui.main_window import MainWindow  # noqa: E402
from test_gui_review import _route_descriptors  # noqa: E402


@pytest.fixture
def boxes(monkeypatch):
    shown: list = []
    for kind in ("critical", "warning", "information"):
        monkeypatch.setattr(QMessageBox, kind, lambda *a, k=kind, **kw: shown.append((k, a[2])) or QMessageBox.Ok)
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **kw: shown.append(("question", a[2])) or QMessageBox.No)
    return shown


@pytest.fixture
def make_window(qtbot, tmp_path, boxes):
    windows = []

    def make() -> MainWindow:
        w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), cache_root=str(tmp_path))
        qtbot.addWidget(w)
        w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("ours"))
        w.show()
        windows.append(w)
        return w

    yield make
    for w in windows:
        w.undo_stack.setClean()
        w._extra_dirty = False
        w.shutdown()


def open_and_run(qtbot, w, path) -> bool:
    with qtbot.waitSignal(w.mapReady, timeout=60_000):
        ok = w.open_path(str(path))
        assert ok
    return ok


def test_a_window_killed_before_saving_loses_no_decision(qtbot, make_window, tmp_path):
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    order = w.loop_table.visible_keys()
    assert len(order) >= 3, "the route should give a few loops"
    w.loop_table.select_keys(order[:2])
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    w.loop_table.select_key(order[2])
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    assert w.doc.journal is not None and len(w.doc.journal.replay()) == 3
    w.shutdown()                                      # no save, no autosave: as if killed

    w2 = make_window()
    open_and_run(qtbot, w2, npz)
    status = {r.key: r.status for r in w2.doc.loop_rows()}
    assert [status[k] for k in order[:3]] == ["confirmed", "confirmed", "rejected"]
    assert w2.isWindowModified()


def test_a_second_window_is_told_the_recording_is_open_elsewhere(qtbot, make_window, tmp_path, boxes):
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    w2 = make_window()
    assert not w2.open_path(str(npz))
    assert boxes and boxes[-1][0] == "critical" and "open in another panotopo" in boxes[-1][1]
    assert not w2.doc.has_map and not w2.runner.running


def test_save_compacts_and_discard_empties_the_journal(qtbot, make_window, tmp_path, monkeypatch):
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    first = w.loop_table.visible_keys()[0]
    w.loop_table.select_key(first)
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    assert w.save_session()
    assert w.doc.journal.replay() == []               # the session holds it now
    w.loop_table.select_key(first)
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    assert len(w.doc.journal.replay()) == 1
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.Discard)
    assert w.maybe_save()
    assert w.doc.journal.replay() == []               # discarded work does not come back
