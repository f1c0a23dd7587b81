"""Decisions written through to the journal (engine.journal) by the real window.

Every decision is on disk when the key is released; a window that dies without saving
loses nothing; a second window is told the recording is open elsewhere; a save
compacts the journal, a discard empties it.
"""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402
from PySide6.QtWidgets import QMessageBox  # noqa: E402

from gui_maps import window_maker, boxes  # noqa: E402,F401  (a fixture)
from test_gui_review import _route_descriptors  # noqa: E402


@pytest.fixture
def make_window(qtbot, tmp_path, boxes):
    yield from window_maker(qtbot, tmp_path, method="ours")


def open_and_run(qtbot, w, path) -> bool:
    with qtbot.waitSignal(w.mapReady, timeout=60_000):
        ok = w.open_path(str(path))
        assert ok
    return ok


def test_a_window_killed_before_saving_loses_no_decision(qtbot, make_window, tmp_path, monkeypatch):
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
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.Yes)  # "Restore unsaved work?"
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


def _decide_three(qtbot, w) -> list:
    order = w.loop_table.visible_keys()
    w.loop_table.select_keys(order[:2])
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    w.loop_table.select_key(order[2])
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    return order


def test_no_to_restore_restores_nothing_and_it_does_not_come_back(qtbot, make_window, tmp_path, boxes):
    """Issue 43, defect 17: answering No still restored everything from the journal."""
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    order = _decide_three(qtbot, w)
    w.shutdown()                                      # killed: the journal holds three decisions
    w2 = make_window()                                # boxes answers No to "Restore unsaved work?"
    open_and_run(qtbot, w2, npz)
    assert any(kind == "question" and "Restore" in text or "unsaved" in text for kind, text in boxes)
    assert all(r.status in ("auto", "candidate") for r in w2.doc.loop_rows() if r.key in order[:3])
    assert not w2.isWindowModified()
    w2.shutdown()
    w3 = make_window()
    before = len(boxes)
    open_and_run(qtbot, w3, npz)
    assert not [b for b in boxes[before:] if b[0] == "question"], "declined work is not offered again"


def test_reopening_the_npz_after_saving_shows_the_saved_decisions(qtbot, make_window, tmp_path):
    """Issue 43, defect 17: the session was found only when its .json was opened."""
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    order = _decide_three(qtbot, w)
    assert w.save_session()
    w.shutdown()
    w2 = make_window()
    open_and_run(qtbot, w2, npz)
    status = {r.key: r.status for r in w2.doc.loop_rows()}
    assert [status[k] for k in order[:3]] == ["confirmed", "confirmed", "rejected"]
    assert w2.doc.session_path is not None and not w2.isWindowModified()


def test_a_clean_quit_leaves_no_journal_or_lock_beside_the_recording(qtbot, make_window, tmp_path):
    """Issue 43, defect 9: an empty journal and a lock were left beside every recording opened."""
    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    assert not list(tmp_path.glob("*.journal")), "nothing decided yet: no journal written"
    w.shutdown()
    assert not list(tmp_path.glob("*.journal*"))
    w2 = make_window()
    open_and_run(qtbot, w2, npz)
    _decide_three(qtbot, w2)
    assert w2.save_session()
    w2.shutdown()
    assert not list(tmp_path.glob("*.journal*")), "saved: the journal holds nothing to keep"


@pytest.mark.parametrize("planted", [".journal", ".journal.lock"])
def test_a_planted_journal_link_is_refused_and_the_window_says_so(qtbot, make_window, tmp_path, boxes, planted):
    """Issue 43, defect 14: a planted journal or lock symlink is refused; the window says nothing
    is journaled (a label that stays), and the link's target is never written."""
    from engine.session import session_path_for

    npz = _route_descriptors(tmp_path / "route.npz")
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    session = session_path_for(npz)
    session.with_name(session.name + planted).symlink_to(victim)
    w = make_window()
    open_and_run(qtbot, w, npz)
    assert w.journal_label.isVisible() and "journal" in w.journal_label.text().lower()
    assert any("NOT journaled" in text for _kind, text in boxes)
    _decide_three(qtbot, w)
    w.shutdown()
    assert victim.read_text() == "keep me"


@pytest.mark.parametrize("name", ["session", "autosave"])
def test_a_planted_session_or_autosave_link_is_never_written_through(qtbot, make_window, tmp_path, boxes, name):
    """Issue 43, defect 14: the autosave and Ctrl+S overwrote the file a planted link named."""
    from engine.session import autosave_path_for, session_path_for

    npz = _route_descriptors(tmp_path / "route.npz")
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    link = (session_path_for if name == "session" else autosave_path_for)(npz)
    w = make_window()
    open_and_run(qtbot, w, npz)
    link.symlink_to(victim)
    _decide_three(qtbot, w)
    if name == "session":
        assert not w.save_session()
        assert any("link" in text for _kind, text in boxes)
    else:
        w.autosave()
    assert victim.read_text() == "keep me"
    assert link.is_symlink(), "the planted link is refused, not replaced"


def test_bad_journal_records_are_skipped_and_counted(qtbot, make_window, tmp_path, boxes, monkeypatch):
    """Issue 43, defect 15: a record with bad fields left the window empty; an unknown status
    reached the session; a garbage line was skipped without a word."""
    import json

    from engine.journal import Journal
    from engine.session import Session, session_path_for

    npz = _route_descriptors(tmp_path / "route.npz")
    w = make_window()
    open_and_run(qtbot, w, npz)
    good = w.loop_table.visible_keys()[0]
    w.shutdown()
    with Journal.open(npz) as j:
        j.append({"op": "status", "frames": "ab", "status": "confirmed"})
        j.append({"op": "status", "frames": [int(good[0]), int(good[1])], "status": "maybe"})
        j.append({"op": "status", "frames": [int(good[0]), int(good[1])], "status": "confirmed"})
        path = j.path
    with open(path, "a") as f:
        f.write("this is not json\n")
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.Yes)
    w2 = make_window()
    open_and_run(qtbot, w2, npz)
    assert {r.key: r.status for r in w2.doc.loop_rows()}[good] == "confirmed"
    assert any("3 journal records" in text for _kind, text in boxes), boxes
    assert w2.save_session()
    assert Session.load(session_path_for(npz)).decisions["loops"]
    json.loads(session_path_for(npz).read_text())
