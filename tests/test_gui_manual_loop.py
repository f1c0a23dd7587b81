"""Adding a loop by hand: the dialog (defect 9) and the yaw the loop keeps (defect 8)."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QSettings  # noqa: E402
from PySide6.QtWidgets import QDialogButtonBox  # noqa: E402

from gui.manual_loop_dialog import ManualLoopDialog, temporal_gap  # noqa: E402
from tests.gui_maps import make_doc  # noqa: E402


def test_dialog_opens_on_any_node_without_a_traceback(qtbot):
    doc = make_doc(None, [(2, 15, "auto")], n=30)
    for first in (0, 7, 29):  # a first node other than 0 used to call _update before it could run
        dialog = ManualLoopDialog(doc, first)
        qtbot.addWidget(dialog)
        assert dialog.nodes()[0] == first


def test_dialog_never_proposes_a_temporal_neighbour(qtbot):
    doc = make_doc(None, [], n=30)
    gap = temporal_gap(doc)
    for first in (0, 7, 29):
        dialog = ManualLoopDialog(doc, first)
        qtbot.addWidget(dialog)
        a, b = dialog.nodes()
        assert abs(a - b) >= gap, f"n{a} is proposed with its neighbour n{b}"
        assert dialog.buttons.button(QDialogButtonBox.Ok).isEnabled()


def test_dialog_proposes_the_most_similar_far_node(qtbot):
    doc = make_doc(None, [], n=30)
    doc.descs.vectors[25] = doc.descs.vectors[3]  # node 25 looks exactly like node 3
    doc.topomap.node_vectors[25] = doc.topomap.node_vectors[3]
    doc._similarity = None
    dialog = ManualLoopDialog(doc, 3)
    qtbot.addWidget(dialog)
    assert dialog.nodes() == (3, 25)


def test_dialog_warns_about_neighbours_and_refuses_joined_nodes(qtbot):
    doc = make_doc(None, [(2, 15, "auto")], n=30)
    dialog = ManualLoopDialog(doc, 10)
    qtbot.addWidget(dialog)
    ok = dialog.buttons.button(QDialogButtonBox.Ok)
    dialog.b.setValue(12)
    assert "neighbour" in dialog.warning.text() and ok.isEnabled()
    dialog.b.setValue(11)
    assert "already joined" in dialog.warning.text() and not ok.isEnabled()
    dialog.a.setValue(2)
    dialog.b.setValue(15)
    assert "already joined" in dialog.warning.text() and not ok.isEnabled()
    dialog.b.setValue(25)
    assert dialog.warning.text() == "" and ok.isEnabled()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from engine.synth import make_recording, write_recording

    out = tmp_path_factory.mktemp("rec")
    rec = make_recording(route="loop", look="indoor", width=256, height=128, fps=2.0, max_frames=120)
    return rec, write_recording(rec, out, formats=("video",))


def test_a_manual_loop_keeps_its_yaw_in_the_session_and_the_graphml(qtbot, tmp_path, recording):
    from gui.main_window import MainWindow

    rec, paths = recording
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat)
    w = MainWindow(settings=settings, cache_root=str(tmp_path / "cache"), describe_options={"input_height": 64})
    qtbot.addWidget(w)
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("shift-simple"))
    try:
        with qtbot.waitSignal(w.mapReady, timeout=120_000):
            assert w.open_path(str(paths["video"]))
        frames = w.doc.node_frames()
        # The two nodes nearest in ground truth, far apart in time: a loop a person would add.
        p = np.stack([rec.poses.x[frames], rec.poses.y[frames]], axis=1)
        d = np.linalg.norm(p[:, None] - p[None], axis=2)
        gap = np.abs(np.arange(len(frames))[:, None] - np.arange(len(frames))[None])
        d[gap < 2 * temporal_gap(w.doc)] = np.inf
        for u, v, _ in w.doc.topomap.loops():
            d[w.doc.node_data(u)["index"], w.doc.node_data(v)["index"]] = np.inf
            d[w.doc.node_data(v)["index"], w.doc.node_data(u)["index"]] = np.inf
        a, b = sorted(np.unravel_index(np.argmin(d), d.shape))
        key = (int(frames[a]), int(frames[b]))
        assert w.add_manual_loop(key)
        yaw = w.doc.loop_attrs(key).get("yaw")
        assert yaw is not None and np.isfinite(yaw), "the manual loop has a yaw"
        manual = [m for m in w.doc.decisions()["manual"] if tuple(m["frames"]) == key]
        assert manual and manual[0]["yaw"] == pytest.approx(yaw), "the session keeps the yaw"
        out = tmp_path / "map.graphml"
        assert w.export_graphml(str(out))
        g = nx.read_graphml(out)
        yaws = [e.get("yaw") for _, _, e in g.edges(data=True) if e.get("status") == "manual"]
        assert yaws and yaws[0] == pytest.approx(yaw, abs=1e-3), "the GraphML keeps the yaw"
    finally:
        w.undo_stack.setClean()
        w._extra_dirty = False
        w.shutdown()


def test_a_neighbour_warning_keeps_both_node_fields_usable(qtbot):
    """Issue 43, defect 4: entering a temporal neighbour showed a four-line warning that
    squashed both node fields to a few pixels."""
    doc = make_doc(None, [], n=30)
    dialog = ManualLoopDialog(doc, 10)
    qtbot.addWidget(dialog)
    dialog.show()
    qtbot.waitExposed(dialog)
    dialog.b.setValue(12)
    qtbot.wait(20)
    assert "neighbour" in dialog.warning.text()
    for box in (dialog.a, dialog.b):
        assert box.height() >= box.sizeHint().height() - 2, "a node field is squashed"
    assert dialog.warning.height() <= 3 * dialog.warning.fontMetrics().height()


def test_the_proposal_is_never_a_pair_already_joined(qtbot):
    """Issue 43, defect 4: the default proposal could be a pair already joined, leaving OK
    disabled with no reason shown."""
    doc = make_doc(None, [(2, 15, "auto")], n=30)
    doc.topomap.node_vectors[15] = doc.topomap.node_vectors[2]   # the joined node is the most similar
    doc._similarity = None
    dialog = ManualLoopDialog(doc, 2)
    qtbot.addWidget(dialog)
    assert dialog.nodes()[1] != 15
    ok = dialog.buttons.button(QDialogButtonBox.Ok)
    assert ok.isEnabled()
    dialog.b.setValue(15)
    assert not ok.isEnabled() and dialog.warning.text() and ok.toolTip()
