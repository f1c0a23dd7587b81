"""The real main window driven through whole sessions on a small synthetic recording.

Runs on Qt's offscreen platform (tests/conftest.py). The engine is real: the
embedded descriptor at a small input size, real videos and bags. Modal message
boxes are replaced by recorders (QMessageBox only, never our code).
"""

from __future__ import annotations

from pathlib import Path

import networkx as nx
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QSettings, Qt  # noqa: E402
from PySide6.QtWidgets import QMessageBox  # noqa: E402

from engine.session import Session, autosave_path_for, session_path_for  # noqa: E402
from gui.main_window import MainWindow  # noqa: E402

OPTIONS = {"input_height": 64}   # small descriptor input: fast, still the real model
METHOD = "shift-simple"          # gives loops on this short recording
RUN_TIMEOUT = 120_000


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from engine.synth import make_recording, write_recording

    out = tmp_path_factory.mktemp("rec")
    rec = make_recording(route="loop", look="indoor", width=256, height=128, fps=2.0, max_frames=160)
    paths = write_recording(rec, out, formats=("video", "poses", "ros1"))
    return paths


@pytest.fixture(scope="module")
def short_video_file(tmp_path_factory):
    """The first 20 s of the route as a video: for the tests that describe it with options of
    their own (nothing shared with the other tests' cache), where no loop is needed."""
    from engine.synth import make_recording, write_recording

    rec = make_recording(route="loop", look="indoor", width=256, height=128, fps=2.0, max_frames=40)
    return write_recording(rec, tmp_path_factory.mktemp("short"), formats=("video",))["video"]


@pytest.fixture
def short_video(short_video_file, tmp_path) -> Path:
    """A copy of it in this test's folder (its sessions stay there)."""
    import shutil

    return Path(shutil.copy(short_video_file, tmp_path / Path(short_video_file).name))


@pytest.fixture(scope="module")
def cache_root(tmp_path_factory):
    return str(tmp_path_factory.mktemp("cache"))


@pytest.fixture
def dialogs(monkeypatch):
    """Record message boxes instead of blocking on them; answers can be queued."""
    calls = _Calls()
    answers = calls.answers

    def record(kind, default):
        def box(parent, title, text, *args, **kwargs):
            calls.append((kind, text))
            return answers.pop(0) if answers else default
        return box

    monkeypatch.setattr(QMessageBox, "critical", record("critical", QMessageBox.Ok))
    monkeypatch.setattr(QMessageBox, "warning", record("warning", QMessageBox.Ok))
    monkeypatch.setattr(QMessageBox, "information", record("information", QMessageBox.Ok))
    monkeypatch.setattr(QMessageBox, "question", record("question", QMessageBox.Discard))
    return calls


class _Calls(list):
    """(kind, text) of each message box shown; ``answers`` are returned in order."""

    def __init__(self) -> None:
        super().__init__()
        self.answers: list = []


@pytest.fixture
def make_window(qtbot, tmp_path, cache_root, dialogs):
    windows = []

    def make() -> MainWindow:
        settings = QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat)
        w = MainWindow(settings=settings, cache_root=cache_root, describe_options=OPTIONS)
        qtbot.addWidget(w)
        w.params_panel.method.setCurrentIndex(w.params_panel.method.findData(METHOD))
        w.resize(1400, 900)
        w.show()
        windows.append(w)
        return w

    yield make
    for w in windows:  # never leave a thread running, never block on a question
        w.undo_stack.setClean()
        w._extra_dirty = False
        w.shutdown()


def open_and_run(qtbot, window: MainWindow, path) -> None:
    with qtbot.waitSignal(window.mapReady, timeout=RUN_TIMEOUT):
        assert window.open_path(str(path))


def statuses(window: MainWindow) -> dict:
    return {r.key: r.status for r in window.doc.loop_rows()}


def copy_recording(recording, tmp_path: Path) -> Path:
    """The shared video (its descriptors stay cached); sessions next to it are removed after each test."""
    return Path(recording["video"])


@pytest.fixture(autouse=True)
def no_sidecars_left(recording):
    yield
    for p in (recording["video"], recording["ros1"]):
        session_path_for(p).unlink(missing_ok=True)
        autosave_path_for(p).unlink(missing_ok=True)
        for suffix in (".journal", ".journal.lock"):  # the decision journal (engine.journal) too
            session = session_path_for(p)
            session.with_name(session.name + suffix).unlink(missing_ok=True)


def test_whole_session_open_run_curate_undo_save_reopen_export(qtbot, make_window, recording, tmp_path, dialogs):
    video = copy_recording(recording, tmp_path)
    w = make_window()
    open_and_run(qtbot, w, video)

    # Every view is filled.
    rows = w.doc.loop_rows()
    assert len(rows) >= 3, "the test recording should give a few loop candidates"
    assert w.loop_table.proxy.rowCount() == len(rows)
    assert w.frame_viewer.current_frame >= 0
    assert w.graph_view.x.size == w.doc.node_count() > 0
    assert w.doc.similarity().shape == (w.doc.node_count(),) * 2
    assert w.doc.poses is not None, "poses.csv next to the recording is loaded"
    assert w.doc.evaluation is not None
    assert not w.isWindowModified()

    # Keyboard curation on the table: confirm the first, reject the next (auto-advance).
    w.loop_table.step(1)
    first = w.loop_table.selected_key()
    assert w.pair_view.key == first
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    assert statuses(w)[first] == "confirmed"
    second = w.loop_table.selected_key()
    assert second != first
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    assert statuses(w)[second] == "rejected"
    assert w.isWindowModified() and "[*]" in w.windowTitle()

    # Undo and redo.
    w.undo_stack.undo()
    assert statuses(w)[second] == "auto"
    w.undo_stack.redo()
    assert statuses(w)[second] == "rejected"

    # Save, close, reopen: the decisions (and where the user was) come back.
    w.frame_viewer.show_frame(33)
    selected = w.loop_table.selected_key()
    assert w.save_session()
    session_file = session_path_for(video)
    assert session_file.is_file() and not w.isWindowModified()
    w.close()
    assert not w.runner.running

    w2 = make_window()
    open_and_run(qtbot, w2, session_file)
    assert statuses(w2)[first] == "confirmed"
    assert statuses(w2)[second] == "rejected"
    assert not w2.isWindowModified()
    assert w2.loop_table.selected_key() == selected
    assert w2.frame_viewer.current_frame == 33

    # Export the corrected graph: rejected left out, confirmed kept with its status.
    out = tmp_path / "corrected.graphml"
    assert w2.export_graphml(str(out))
    g = nx.read_graphml(out)
    frame_node = {int(d["frame"]): n for n, d in g.nodes(data=True)}
    a, b = (frame_node[f] for f in first)
    assert g.has_edge(a, b) and g.edges[a, b]["status"] == "confirmed"
    c, d = (frame_node[f] for f in second)
    assert not g.has_edge(c, d)
    assert all(e["status"] != "rejected" for _, _, e in g.edges(data=True))
    png = tmp_path / "graph.png"
    assert w2.export_graph_png(str(png)) and png.stat().st_size > 1000
    assert not [c for c in dialogs if c[0] == "critical"]


def test_parameter_change_rebuilds_at_once_and_keeps_decisions(qtbot, make_window, recording, tmp_path):
    w = make_window()
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    w.loop_table.step(1)
    key = w.loop_table.selected_key()
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    before = w.doc.topomap
    old_th = w.params_panel.loop_sim_th.value()

    with qtbot.waitSignal(w.mapReady, timeout=5000):
        w.params_panel.loop_sim_th.setValue(old_th - 0.03)
    assert w.doc.topomap is not before
    assert w.doc.params.loop_sim_th == pytest.approx(old_th - 0.03)
    assert statuses(w)[key] == "confirmed"
    assert len(w.doc.loop_rows()) >= len(before.loops())

    w.undo_stack.undo()  # the parameter change is undone, the decision stays
    assert w.params_panel.loop_sim_th.value() == pytest.approx(old_th)
    assert statuses(w)[key] == "confirmed"
    w.undo_stack.undo()  # then the decision
    assert statuses(w)[key] == "auto"


def test_verified_shows_the_node_threshold_it_calibrated(qtbot, make_window, recording, tmp_path):
    w = make_window()
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("verified"))
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    assert w.doc.params.node_sim_th is None              # left unset: calibrated per recording
    used = w.doc.topomap.meta["node_sim_th"]
    assert used != pytest.approx(w.runs._defaults["node_sim_th"], abs=1e-3)
    assert w.params_panel.node_sim_th.value() == pytest.approx(used, abs=1e-3)
    with qtbot.waitSignal(w.mapReady, timeout=5000):   # another parameter: still the calibrated value
        w.params_panel.neighbor_node_num.setValue(w.params_panel.neighbor_node_num.value() + 1)
    assert w.params_panel.node_sim_th.value() == pytest.approx(w.doc.topomap.meta["node_sim_th"], abs=1e-3)


def test_a_verified_threshold_remaps_and_undo_restores_it(qtbot, make_window, recording, tmp_path):
    w = make_window()
    panel = w.params_panel
    panel.method.setCurrentIndex(panel.method.findData("verified"))
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    before = w.doc.params
    box = panel.evidence["auto_inliers"]
    with qtbot.waitSignal(w.mapReady, timeout=30_000):  # a generated row, through the same undoable path
        box.setValue(before.auto_inliers + 15)
    assert w.doc.params.auto_inliers == before.auto_inliers + 15
    assert w.doc.topomap.meta["auto_inliers"] == before.auto_inliers + 15   # the map was built with it
    with qtbot.waitSignal(w.mapReady, timeout=30_000):  # the group's Defaults: one more undo step
        qtbot.mouseClick(panel.defaults_button, Qt.LeftButton)
    assert w.doc.params == before and w.doc.topomap.meta["auto_inliers"] == before.auto_inliers
    with qtbot.waitSignal(w.mapReady, timeout=30_000):
        w.undo_stack.undo()                             # back to the edited value
    assert w.doc.params.auto_inliers == box.value() == before.auto_inliers + 15
    with qtbot.waitSignal(w.mapReady, timeout=30_000):
        w.undo_stack.undo()                             # and to the table's value
    assert w.doc.params == before and box.value() == before.auto_inliers
    assert w.doc.topomap.meta["auto_inliers"] == before.auto_inliers


def test_thresholds_from_the_recording_are_one_undo_step(qtbot, make_window, recording, tmp_path):
    from engine.calibrate import paper_thresholds

    w = make_window()                                    # shift-simple: a paper method
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    before = w.doc.params
    expected = paper_thresholds(w.doc.descs.vectors, before.neighbor_node_num)
    assert w.params_panel.calibrate_button.isEnabled()
    with qtbot.waitSignal(w.mapReady, timeout=5000):
        qtbot.mouseClick(w.params_panel.calibrate_button, Qt.LeftButton)
    assert w.doc.params.loop_sim_th == pytest.approx(expected["loop_sim_th"])
    assert w.doc.params.node_sim_th == pytest.approx(expected["node_sim_th"])
    assert w.params_panel.loop_sim_th.value() == pytest.approx(expected["loop_sim_th"], abs=1e-3)
    assert w.doc.topomap.meta["loop_sim_th"] == pytest.approx(expected["loop_sim_th"])
    w.undo_stack.undo()
    assert w.doc.params == before
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("verified"))
    assert not w.params_panel.calibrate_button.isEnabled()   # verified calibrates by itself


def test_switching_to_simple_describes_again_and_keeps_decisions(qtbot, make_window, recording, tmp_path):
    w = make_window()
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    w.loop_table.step(1)
    key = w.loop_table.selected_key()
    qtbot.keyClick(w.loop_table.view, Qt.Key_R)
    decisions = w.doc.decisions()
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("simple"))
    assert w.doc.descs.meta["shift"] is False
    assert w.doc.params.method == "simple"
    # The rejection is kept (applied, or carried as unapplied when simple has no such loop).
    assert decisions["loops"][0] in w.doc.decisions()["loops"]
    assert key in statuses(w) or w.doc.topomap.unapplied["loops"]


def _photometric(descs) -> str:
    return descs.meta["settings"].get("photometric", "none")


def test_the_method_decides_the_describe_options_in_the_app(qtbot, make_window, short_video, tmp_path, dialogs):
    """verified's descriptors are standardised: switching to ours describes again, plainly (not
    a bare remap), and back; a verified parameter only remaps. A descriptors file is what it
    is: either method maps it, only a method needing another shift is refused."""
    w = make_window()
    panel = w.params_panel
    runs: list = []
    w.runner.started.connect(lambda: runs.append(panel.method.currentData()))
    panel.method.setCurrentIndex(panel.method.findData("verified"))
    open_and_run(qtbot, w, short_video)
    assert _photometric(w.doc.descs) == "standardise"
    assert "photometric" not in w.doc.describe_settings.options      # the user's own settings stay plain
    for method, expected in (("ours", "none"), ("verified", "standardise")):
        with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
            panel.method.setCurrentIndex(panel.method.findData(method))
            assert w.runner.running                                   # describing again, not remapping
        assert _photometric(w.doc.descs) == expected and w.doc.topomap.meta["method"] == method
    assert runs == ["verified", "ours", "verified"]
    with qtbot.waitSignal(w.mapReady, timeout=30_000):
        panel.neighbor_node_num.setValue(panel.neighbor_node_num.value() + 1)
        assert not w.runner.running                                   # same descriptors: a remap
    assert len(runs) == 3 and w.doc.topomap.meta["neighbor_node_num"] == panel.neighbor_node_num.value()

    npz = tmp_path / "standardised.npz"
    w.doc.descs.save(npz)
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        assert w.open_path(str(npz))
    with qtbot.waitSignal(w.mapReady, timeout=30_000):
        panel.method.setCurrentIndex(panel.method.findData("ours"))
        assert not w.runner.running                                   # mapped as it is
    assert w.doc.topomap.meta["method"] == "ours" and _photometric(w.doc.descs) == "standardise"
    assert not [text for kind, text in dialogs if kind == "warning"]
    panel.method.setCurrentIndex(panel.method.findData("simple"))     # unshifted: the file cannot serve
    assert [text for kind, text in dialogs if kind == "warning" and "unshifted" in text]
    assert not w.runner.running and w.doc.topomap.meta["method"] == "ours"


def test_cancelled_run_leaves_map_and_decisions_untouched(qtbot, make_window, recording, tmp_path):
    w = make_window()
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    w.loop_table.step(1)
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    topomap, decisions = w.doc.topomap, w.doc.decisions()

    w.params_panel.interval.setValue(0.5)  # not cached: a real describe that we cancel
    with qtbot.waitSignal(w.runCancelled, timeout=RUN_TIMEOUT):
        w.start_run()
        assert w.runner.running
        w.cancel_run()
    assert not w.runner.running
    assert w.doc.topomap is topomap
    assert w.doc.decisions() == decisions
    assert not w.progress_bar.isVisible()


def test_closing_during_a_run_stops_the_thread(qtbot, make_window, recording, tmp_path):
    w = make_window()
    assert w.open_path(str(copy_recording(recording, tmp_path)))
    w.params_panel.interval.setValue(0.75)
    w.start_run()
    thread = w.runner.worker._threads[-1]     # the run's thread (gui.background.Worker)
    assert thread is not None and thread.isRunning()
    w.close()
    assert not thread.isRunning()
    assert not w.runner.running


@pytest.mark.parametrize("name, content", [
    ("broken.mp4", b"this is not a video"),
    ("broken.panotopo.json", b"{ half a session"),
    ("broken.npz", b"PK\x03\x04 not a zip"),
    ("missing.bag", None),
])
def test_bad_input_shows_a_message_not_a_crash(qtbot, make_window, tmp_path, dialogs, name, content):
    w = make_window()
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    assert not w.open_path(str(path))
    kinds = [k for k, _ in dialogs]
    assert kinds == ["critical"]
    assert name in dialogs[0][1] or str(path) in dialogs[0][1]
    assert "Traceback" not in dialogs[0][1]
    assert not w.doc.has_map and not w.runner.running


def test_manual_loop_label_and_their_undo(qtbot, make_window, recording, tmp_path):
    w = make_window()
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    frames = w.doc.node_frames()
    key = (int(frames[3]), int(frames[20]))
    assert w.doc.loop_attrs(key) is None
    assert w.add_manual_loop(key)
    assert statuses(w)[key] == "manual"
    assert w.loop_table.selected_key() == key
    w.remove_manual_loop(key)
    assert key not in statuses(w)
    w.undo_stack.undo()
    assert statuses(w)[key] == "manual"
    w.undo_stack.undo()
    assert key not in statuses(w)

    w.set_label(int(frames[5]), "kitchen")
    assert w.doc.node_data(w.doc.node_id(5))["label"] == "kitchen"
    assert len(w.graph_view.label_items) == 1
    w.undo_stack.undo()
    assert w.doc.node_data(w.doc.node_id(5)).get("label", "") == ""
    assert w.graph_view.label_items == []


def test_graph_and_matrix_clicks_select(qtbot, make_window, recording, tmp_path):
    w = make_window()
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    qtbot.wait(50)
    # A node click jumps to that node's frame.
    k = w.doc.node_count() // 2
    pos = w.graph_view.node_screen_pos(k)
    qtbot.mouseClick(w.graph_view.plot.viewport(), Qt.LeftButton, pos=pos)
    assert w.frame_viewer.current_frame == int(w.doc.node_frames()[k])

    # A matrix cell with a loop selects it in the table; one without shows the pair.
    w.tabs.setCurrentWidget(w.similarity_view)
    qtbot.waitUntil(w.doc.similarity_ready, timeout=10_000)  # computed off the UI thread
    qtbot.wait(50)
    row = w.doc.loop_rows()[0]
    w.similarity_view._clicked(_FakeClick(w.similarity_view.cell_scene_pos(row.index_u, row.index_v)))
    assert w.loop_table.selected_key() == row.key
    w.similarity_view._clicked(_FakeClick(w.similarity_view.cell_scene_pos(0, 2)))
    assert w.loop_table.selected_key() is None
    assert w.pair_view.key == (int(w.doc.node_frames()[0]), int(w.doc.node_frames()[2]))
    assert w.pair_view.add_button.isEnabled()


class _FakeClick:
    """What pyqtgraph's scene passes to sigMouseClicked (its real event needs a drag state machine)."""

    def __init__(self, scene_pos):
        self._pos = scene_pos
        self.accepted = False

    def button(self):
        return Qt.LeftButton

    def scenePos(self):
        return self._pos

    def modifiers(self):
        return Qt.NoModifier

    def accept(self):
        self.accepted = True


def test_live_evaluation_follows_decisions(qtbot, make_window, recording, tmp_path):
    w = make_window()
    open_and_run(qtbot, w, copy_recording(recording, tmp_path))
    ev = w.doc.evaluation
    truth = ev.loop_truth
    row = next(r for r in w.doc.loop_rows() if truth.get((r.u, r.v)) == "TP")
    w.loop_table.select_key(row.key)
    qtbot.keyClick(w.loop_table.view, Qt.Key_N)
    assert w.doc.evaluation.tp == ev.tp - 1
    assert w.doc.evaluation.fn == ev.fn + 1
    assert w.eval_panel.values["tp"].text() == f"<b>{ev.tp - 1}</b>"


def test_autosave_restores_unsaved_decisions(qtbot, make_window, recording, tmp_path, dialogs):
    video = copy_recording(recording, tmp_path)
    w = make_window()
    open_and_run(qtbot, w, video)
    w.loop_table.step(1)
    key = w.loop_table.selected_key()
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    w.autosave_timer.timeout.emit()  # what the 30 s timer does
    auto = autosave_path_for(video)
    assert auto.is_file() and not session_path_for(video).exists()
    assert Session.load(auto).decisions["loops"][0]["status"] == "confirmed"
    w.shutdown()  # as if the app had crashed: nothing saved

    w2 = make_window()
    dialogs.answers.append(QMessageBox.Yes)  # "Restore unsaved work?"
    open_and_run(qtbot, w2, video)
    assert statuses(w2)[key] == "confirmed"
    assert w2.isWindowModified()


def test_close_asks_before_losing_work(qtbot, make_window, recording, tmp_path, dialogs):
    video = copy_recording(recording, tmp_path)
    w = make_window()
    open_and_run(qtbot, w, video)
    w.loop_table.step(1)
    qtbot.keyClick(w.loop_table.view, Qt.Key_Y)
    dialogs.answers.append(QMessageBox.Cancel)
    assert not w.close()  # Cancel keeps the window
    assert w.isVisible() and w.isWindowModified()
    dialogs.answers.append(QMessageBox.Save)
    assert w.close()
    assert session_path_for(video).is_file()
    assert [k for k, _ in dialogs].count("question") == 2


def test_bag_with_topic_and_pose_topic(qtbot, make_window, recording, tmp_path):
    from engine.sources import list_image_topics, list_pose_topics

    from gui.open_dialog import BagTopicDialog

    bag = recording["ros1"]
    images, poses = list_image_topics(bag), list_pose_topics(bag)
    dialog = BagTopicDialog(str(bag), images, poses)
    qtbot.addWidget(dialog)
    chosen_image, chosen_pose = dialog.chosen()
    assert chosen_image == max(images, key=lambda t: t[2])[0]
    assert chosen_pose == (poses[0][0] if poses else None)

    w = make_window()
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        assert w.open_path(str(bag), topic=chosen_image, pose_topic=chosen_pose)
    assert w.doc.source.frame_count == 160
    if chosen_pose:
        assert w.doc.poses is not None and w.doc.poses_topic == chosen_pose
    assert w.doc.node_count() > 0


def _answer_topic_dialog(qtbot, choose_pose: bool, accept: bool) -> None:
    """When the modal bag dialog shows, pick the pose choice and press Open (or Cancel)."""
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication, QDialogButtonBox

    from gui.open_dialog import BagTopicDialog

    def answer():
        dialog = QApplication.activeModalWidget()
        if not isinstance(dialog, BagTopicDialog):
            QTimer.singleShot(50, answer)
            return
        dialog.pose_topic.setCurrentIndex(1 if choose_pose else 0)
        box = dialog.findChild(QDialogButtonBox)
        button = box.button(QDialogButtonBox.Open if accept else QDialogButtonBox.Cancel)
        qtbot.mouseClick(button, Qt.LeftButton)

    QTimer.singleShot(50, answer)


def test_bag_topic_dialog_clicked_through(qtbot, make_window, recording):
    w = make_window()
    assert w.interactive
    _answer_topic_dialog(qtbot, choose_pose=False, accept=False)     # Cancel: nothing opens
    assert w.open_path(str(recording["ros1"])) is False
    assert w.doc.descs is None
    _answer_topic_dialog(qtbot, choose_pose=True, accept=True)       # Open with the pose topic
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        assert w.open_path(str(recording["ros1"]))
    assert w.doc.node_count() > 0
    assert w.doc.poses is not None and w.doc.poses_topic


def test_recent_files_and_frame_keys(qtbot, make_window, recording, tmp_path):
    video = copy_recording(recording, tmp_path)
    w = make_window()
    open_and_run(qtbot, w, video)
    assert w.recent_files()[0] == str(video.resolve())
    assert any(a.text() == str(video.resolve()) for a in w.recent_menu.actions())
    w.frame_viewer.show_frame(10)
    qtbot.keyClick(w.frame_viewer, Qt.Key_Right)
    assert w.frame_viewer.current_frame == 11
    qtbot.keyClick(w.frame_viewer, Qt.Key_Left)
    qtbot.keyClick(w.frame_viewer, Qt.Key_Left)
    assert w.frame_viewer.current_frame == 9
    qtbot.keyClick(w.frame_viewer, Qt.Key_End)
    assert w.frame_viewer.current_frame == w.doc.source.frame_count - 1
    assert "frame" in w.frame_viewer.info.text()
    frame = w.frames.get(9)
    assert frame is not None and 0 <= frame.shift < frame.rgb.shape[1]


def test_graph_loop_click_and_ctrl_click_manual_loop(qtbot, make_window, recording, dialogs):
    w = make_window()
    open_and_run(qtbot, w, recording["video"])
    qtbot.wait(50)
    w.doc.set_poses(None, None)  # the path layout
    qtbot.wait(50)
    gv = w.graph_view
    import pyqtgraph as pg

    # Click a loop curve drawn on the layout (it bulges off the path) where no node is near:
    # it is selected in the table.
    vb = gv.plot.getPlotItem().getViewBox()
    spots = [(key, pt) for (key, _, _), curve in zip(gv._loop_segments, gv._loop_curves) for pt in curve
             if gv.nearest_node(*pt)[1] > 12 and gv.nearest_loop(*pt)[0] == key]
    assert spots, "some part of a loop curve is away from the nodes"
    key, pt = spots[len(spots) // 2]
    row = next(r for r in w.doc.loop_rows() if r.key == key)
    pos = gv.plot.mapFromScene(vb.mapViewToScene(pg.Point(*pt)))
    qtbot.mouseClick(gv.plot.viewport(), Qt.LeftButton, pos=pos)
    assert w.loop_table.selected_key() == row.key

    # Select a node (plain click), then Ctrl+click another: a manual loop, undoable.
    gv.plot.autoRange()
    qtbot.wait(50)
    n = w.doc.node_count()
    first, second = 1, n - 2
    qtbot.mouseClick(gv.plot.viewport(), Qt.LeftButton, pos=gv.node_screen_pos(first))
    assert gv.current_node == first
    key = w.doc.key_of_nodes(first, second)
    dialogs.answers.append(QMessageBox.No)   # Ctrl+click asks first (issue 14, defect 10): No adds nothing
    qtbot.mouseClick(gv.plot.viewport(), Qt.LeftButton, Qt.ControlModifier, pos=gv.node_screen_pos(second))
    assert key not in statuses(w)
    assert [k for k, _ in dialogs] == ["question"]
    dialogs.answers.append(QMessageBox.Yes)
    qtbot.mouseClick(gv.plot.viewport(), Qt.LeftButton, Qt.ControlModifier, pos=gv.node_screen_pos(second))
    assert statuses(w)[key] == "manual"
    w.undo_stack.undo()
    assert key not in statuses(w)


def test_drop_a_file_opens_it(qtbot, make_window, recording):
    from PySide6.QtCore import QMimeData, QPointF, QUrl
    from PySide6.QtGui import QDropEvent

    w = make_window()
    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(recording["video"]))])
    event = QDropEvent(QPointF(100, 100), Qt.CopyAction, mime, Qt.LeftButton, Qt.NoModifier)
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        w.dropEvent(event)
    assert w.doc.input_path == Path(recording["video"])


def test_shortcuts_dialog_lists_the_curation_keys(qtbot):
    from gui.shortcuts_dialog import ShortcutsDialog

    d = ShortcutsDialog()
    qtbot.addWidget(d)
    table = d.layout().itemAt(0).widget()
    keys = {table.item(r, 1).text() for r in range(table.rowCount())}
    assert {"C or Y", "R or N", "Ctrl+Z"} <= keys


def test_table_sorting_and_status_filter(qtbot, make_window, recording):
    from gui.loop_table import COLUMNS

    w = make_window()
    open_and_run(qtbot, w, recording["video"])
    table = w.loop_table
    table.step(1)
    selected = table.selected_key()
    table.view.sortByColumn(COLUMNS.index("Sim."), Qt.DescendingOrder)  # similarity, highest first
    shown = [table.proxy.index(r, COLUMNS.index("Sim.")).data() for r in range(table.proxy.rowCount())]
    assert shown == sorted(shown, reverse=True)
    assert table.selected_key() == selected  # the selection follows its row
    qtbot.keyClick(table.view, Qt.Key_C)
    only = table.filter.findText("Confirmed")
    table.filter.setCurrentIndex(only)
    assert table.proxy.rowCount() == 1
    assert table.proxy.index(0, 1).data() == "confirmed"
    table.filter.setCurrentIndex(table.filter.findText("Undecided (candidate + auto)"))
    assert table.proxy.rowCount() == len(w.doc.loop_rows()) - 1


def test_node_panel_names_a_place(qtbot, make_window, recording):
    w = make_window()
    open_and_run(qtbot, w, recording["video"])
    frame = int(w.doc.node_frames()[4])
    w.frame_viewer.show_frame(frame)
    assert w.node_panel.node_index == 4
    w.node_panel.name.setFocus()
    qtbot.keyClicks(w.node_panel.name, "lab door")
    qtbot.keyClick(w.node_panel.name, Qt.Key_Return)
    assert w.doc.label_of_frame(frame) == "lab door"
    assert "lab door" in w.frame_viewer.info.text()
    w.undo_stack.undo()
    assert w.doc.label_of_frame(frame) == ""


def test_progress_bar_and_eta_follow_the_run(qtbot, make_window, recording):
    w = make_window()
    w.params_panel.interval.setValue(1.5)  # not cached by other tests: a real describe with progress
    seen = []
    w.runner.progress.connect(lambda done, total, stage: seen.append((done, total, stage)))
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        assert w.open_path(str(recording["video"]))
        qtbot.waitUntil(lambda: any(t > 0 for _, t, _ in seen), timeout=RUN_TIMEOUT)
        assert w.progress_bar.isVisible() and w.cancel_button.isEnabled()
        assert w.progress_bar.maximum() > 0 and ":" in w.progress_bar.format()
    assert not w.progress_bar.isVisible()
    assert seen[-1][0] <= seen[-1][1] or seen[-1][1] == 0


def test_failed_run_keeps_map_and_decisions(qtbot, make_window, recording, tmp_path, dialogs):
    import shutil

    video = tmp_path / "copy.mp4"
    shutil.copy(recording["video"], video)
    w = make_window()
    open_and_run(qtbot, w, video)
    w.loop_table.step(1)
    qtbot.keyClick(w.loop_table.view, Qt.Key_C)
    topomap, decisions = w.doc.topomap, w.doc.decisions()
    video.write_bytes(b"the recording got damaged")  # the next describe cannot read it
    w.params_panel.interval.setValue(2.0)
    with qtbot.waitSignal(w.runFailed, timeout=RUN_TIMEOUT):
        w.start_run()
    assert w.doc.topomap is topomap and w.doc.decisions() == decisions
    assert [k for k, _ in dialogs] == ["critical"] and "Traceback" not in dialogs[0][1]
    assert not w.runner.running and w.isWindowModified()


def test_the_panel_photometric_choice_wins_over_the_method_and_is_saved(qtbot, make_window, short_video, tmp_path):
    """The Descriptors group's Photometric row: a named choice is the user's (kept in the
    session, used whatever the method); "as the method asks" leaves it to the method again.
    The row is there only for a descriptor that has the option."""
    w = make_window()
    panel = w.params_panel
    panel.method.setCurrentIndex(panel.method.findData("verified"))
    assert panel.photometric.isVisibleTo(panel) and panel.photometric_choice() is None
    panel.photometric.setCurrentIndex(panel.photometric.findData("none"))
    open_and_run(qtbot, w, short_video)
    assert _photometric(w.doc.descs) == "none"                       # not what verified asks
    assert w.current_session().describe["options"]["photometric"] == "none"
    assert panel.photometric_choice() == "none"
    panel.set_photometric(None)
    assert panel.photometric_choice() is None
    with qtbot.waitSignal(w.mapReady, timeout=RUN_TIMEOUT):
        w.start_run()
    assert _photometric(w.doc.descs) == "standardise"
    assert "photometric" not in w.current_session().describe["options"]
    panel.descriptor.setCurrentIndex(panel.descriptor.findText("anyloc-gem"))
    assert not panel.photometric.isVisibleTo(panel)
