"""A site of three recordings in the real window: opened, curated across recordings, saved, reopened.

The recordings are made here (tests/test_gui_site_model.py, ``make_site_files``): folders
of frames whose pixels name their recording and frame, with a descriptors .npz each; A and
B share their places, C is another world. Every check is a property of the site (which
recording a node, a loop or a frame belongs to), not a count on a seed.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402
from PySide6.QtWidgets import QMessageBox  # noqa: E402

from gui_maps import window_maker, boxes, colour_pixels  # noqa: E402,F401  (a fixture)
from test_gui_site_model import NAMES, frame_code, make_site_files  # noqa: E402

AB = ("A.npz", "B.npz")


@pytest.fixture
def make_window(qtbot, tmp_path, boxes):
    yield from window_maker(qtbot, tmp_path, method="verified", size=(1280, 720))


def open_site(qtbot, w, paths) -> None:
    """Open ``paths`` together and wait for the map (a failed run fails at once, with its reason)."""
    outcome: list = []
    w.mapReady.connect(lambda: outcome.append("ready"))
    w.runFailed.connect(outcome.append)
    assert w.open_paths([str(p) for p in paths])
    qtbot.waitUntil(lambda: bool(outcome), timeout=60_000)
    assert outcome[0] == "ready", outcome[0]


def across(w, pair=AB) -> list:
    return [r for r in w.doc.loop_rows() if r.sessions == pair]


def test_a_site_of_three_recordings_opens_with_a_colour_and_a_name_each(qtbot, make_window, tmp_path, boxes):
    from engine.graph import TopoMap
    from gui.style import recording_color

    files = make_site_files(tmp_path / "site")
    w = make_window()
    open_site(qtbot, w, [files[n] for n in NAMES])
    site = w.doc.site
    assert site.names == ["A.npz", "B.npz", "C.npz"] and not boxes
    # the site file is written beside the first recording, and names the three recordings
    assert site.anchor.parent == Path(files["A"]).parent and site.anchor.is_file() and not site.new
    assert [r["session"] for r in TopoMap.read_graphml(site.anchor).session_records()] == site.names
    assert w.windowTitle().startswith(site.anchor.name)
    # every recording has nodes, each drawn in its own colour, its path apart from the others'
    sessions = w.doc.topomap.node_sessions()
    assert set(sessions) == set(site.names)
    view = w.graph_view
    assert view.legend.isVisible() and all(name in view.legend.text() for name in site.names)
    assert len(view.recording_items) == 3 and view.sequential_item.xData is None or len(view.sequential_item.xData) == 0
    for i, item in enumerate(view.recording_items):
        assert len(item.xData) == 2 * (np.count_nonzero(sessions == site.names[i]) - 1)  # no arc to another recording
        assert colour_pixels(view.plot, recording_color(i), tol=30) > 20
    assert len(view.start_item.data) == 3 and len(view.end_item.data) == 3
    # the queue holds loops within and across recordings; the pair filter lists every pair
    table = w.loop_table
    assert table.pair_filter.isVisible() and table.pair_filter.count() == 1 + 6
    assert across(w), "B drives A's route backwards: loops join them"
    assert table.set_pair(("B.npz", "A.npz"))       # either way round
    shown = table.visible_keys()
    assert shown and sorted(shown) == sorted(r.key for r in across(w))
    assert table.set_pair(("A.npz", "C.npz")) and table.visible_keys() == []   # C is another world
    assert table.set_pair(None) and len(table.visible_keys()) == len(w.doc.loop_rows())
    # the frame viewer names the recording of the frame it shows
    w.curation.show_node(int(np.flatnonzero(sessions == "C.npz")[3]))
    assert "C.npz" in w.frame_viewer.info.text()


def test_the_pair_view_shows_each_frame_from_its_own_recording(qtbot, make_window, tmp_path):
    from PIL import Image

    files = make_site_files(tmp_path / "site")
    w = make_window()
    open_site(qtbot, w, [files[n] for n in NAMES])
    row = across(w)[0]
    w.select_loop(row.key)
    assert w.pair_view.key == row.key
    (sa, fa), (sb, fb) = (w.doc.site.local(f) for f in row.key)
    assert (sa, sb) == AB and fa < 30 and fb < 30
    query, cand = w.pair_view.query_image.image, w.pair_view.cand_image.image
    assert tuple(query[0, 0, :2]) == frame_code(0, fa) and tuple(cand[0, 0, :2]) == frame_code(1, fb)
    own = np.asarray(Image.open(Path(files["A_frames"]) / f"frame_{fa:04d}.png"))
    assert np.array_equal(query, own)                   # A's frame, read from A's folder, A's frame number
    assert "A.npz frame" in w.pair_view.title.text() and "B.npz frame" in w.pair_view.title.text()
    # the frame viewer follows the selected loop into its recording
    assert "A.npz" in w.frame_viewer.info.text()


def _confirm_across(qtbot, w):
    """Confirm one loop across A and B and reject another (keys pressed in the queue)."""
    rows = across(w)
    assert len(rows) >= 2
    w.advance_after_decision = False
    w.loop_table.select_key(rows[0].key)
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    w.loop_table.select_key(rows[1].key)
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    return [w.doc.address(r.key) for r in rows[:2]]


def _statuses(w) -> dict:
    return {tuple(map(tuple, w.doc.address(r.key))): r.status for r in w.doc.loop_rows()}


def test_decisions_across_recordings_survive_save_and_reopen(qtbot, make_window, tmp_path):
    files = make_site_files(tmp_path / "site")
    w = make_window()
    open_site(qtbot, w, [files[n] for n in NAMES])
    confirmed, rejected = _confirm_across(qtbot, w)
    assert w.save_session()
    anchor = w.doc.site.anchor
    w.shutdown()

    w2 = make_window()
    open_site(qtbot, w2, [anchor])           # the site file, as File ▸ Open or the recent list gives it
    statuses = _statuses(w2)
    assert statuses[tuple(map(tuple, confirmed))] == "confirmed"
    assert statuses[tuple(map(tuple, rejected))] == "rejected"
    assert not w2.isWindowModified()
    # a parameter change re-maps the site (each recording its own nodes) and keeps the decisions
    before = w2.doc.topomap
    with qtbot.waitSignal(w2.mapReady, timeout=30_000):
        w2.params_panel.neighbor_node_num.setValue(w2.params_panel.neighbor_node_num.value() + 1)
    assert w2.doc.topomap is not before and set(w2.doc.topomap.node_sessions()) == set(w2.doc.site.names)
    assert w2.doc.topomap.session_records() == before.session_records()
    assert _statuses(w2)[tuple(map(tuple, confirmed))] == "confirmed"


def test_decisions_across_recordings_survive_a_kill_and_a_moved_recording(qtbot, make_window, tmp_path, boxes,
                                                                         monkeypatch):
    files = make_site_files(tmp_path / "site")
    w = make_window()
    open_site(qtbot, w, [files[n] for n in NAMES])
    confirmed, rejected = _confirm_across(qtbot, w)
    records = w.doc.journal.replay()
    assert len(records) == 2 and all(sorted(r["sessions"]) == list(AB) for r in records)
    anchor = w.doc.site.anchor
    w.shutdown()                             # no save, no autosave: as if killed

    # B's descriptors moved away meanwhile: one line, no traceback, nothing opened, nothing lost
    moved = tmp_path / "B_elsewhere.npz"
    shutil.move(files["B"], moved)
    w2 = make_window()
    assert not w2.open_path(str(anchor))
    kind, text = boxes[-1]
    assert kind == "critical" and "B.npz" in text and "\n" not in text and "Traceback" not in text
    assert not w2.doc.has_map and not w2.runner.running
    assert not w2.open_paths([files["A"], files["B"]])   # a missing descriptors file, chosen with others
    assert boxes[-1][0] == "critical" and "\n" not in boxes[-1][1]

    shutil.move(moved, files["B"])           # back where the site says
    w3 = make_window()
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.Yes)   # "Restore unsaved work?"
    open_site(qtbot, w3, [files[n] for n in NAMES])   # the same recordings chosen again: the same site
    assert w3.doc.site.anchor == anchor
    statuses = _statuses(w3)
    assert statuses[tuple(map(tuple, confirmed))] == "confirmed"
    assert statuses[tuple(map(tuple, rejected))] == "rejected"
    assert w3.isWindowModified()


def test_a_recording_whose_frames_moved_still_maps_and_says_so_in_one_line(qtbot, make_window, tmp_path, boxes):
    files = make_site_files(tmp_path / "site")
    shutil.move(files["C_frames"], tmp_path / "C_frames_elsewhere")
    w = make_window()
    open_site(qtbot, w, [files[n] for n in NAMES])
    warnings = [text for kind, text in boxes if kind == "warning"]
    assert len(warnings) == 1 and "C.npz" in warnings[0] and "\n" not in warnings[0]
    assert "C.npz" in set(w.doc.topomap.node_sessions())
    k = int(np.flatnonzero(w.doc.topomap.node_sessions() == "C.npz")[0])
    assert w.frames.get(w.doc.node_place(k)) is None                 # no frame of C: none made up
    row = across(w)[0]
    w.select_loop(row.key)                   # A and B still show their frames
    assert w.pair_view.query_image.image is not None
