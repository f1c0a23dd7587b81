"""The main window: menus, docks, the run, curation, sessions and export.

Layout: left the frame viewer; right top the graph view and the similarity
matrix in tabs; right bottom the loop table beside the pair view; docks for the
parameters and the evaluation.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Optional

from PySide6.QtCore import QEvent, QKeyCombination, QSettings, Qt, QTimer, Signal
from PySide6.QtGui import QAction, QCloseEvent, QDragEnterEvent, QDropEvent, QIcon, QKeySequence, QUndoStack
from PySide6.QtWidgets import (QApplication, QDockWidget, QFileDialog, QInputDialog, QLabel, QLineEdit, QMainWindow,
                               QMessageBox, QProgressBar, QPushButton, QSplitter, QTabWidget)

from engine.errors import InputError
from engine.journal import JournalLocked
from engine.params import MapParams
from engine.session_fields import LABEL_MAX
from engine.session import Session, autosave_path_for, is_session_file, session_path_for

from .background import Worker
from .commands import ChangeParams, QtHistory
from .document import Document, LoopKey
from .eval_panel import EvalPanel
from .frame_cache import FrameCache
from .frame_viewer import FrameViewer
from .graph_view import GraphView
from .model.layout import path_layout
from .loop_table import LoopTable
from .manual_loop_dialog import ManualLoopDialog
from .model import commands as edits
from .model.document import needs_remap
from .model.keys import bad_overrides, shortcut_table
from .model.queue import ReviewQueue
from .model.recording_files import RecordingFiles, Unsaved
from .node_panel import NodePanel
from .pair_evidence import pair_yaw
from .pair_view import PairView
from .window_layout import fit_to_screen, split_views
from .params_panel import ParamsPanel, photometric_applies
from .similarity_view import SimilarityView
from .worker import FinishedRun, RunController, RunJob

APP_NAME = "panotopo"
FOCUS_FRAME = "border: 2px solid #3daee9;"  # the frame viewer has the keyboard
OPEN_FILTER = ("Recordings and sessions (*.mp4 *.avi *.mkv *.mov *.webm *.m4v *.bag *.db3 *.mcap "
               "*.panotopo.json *.json *.npz);;Videos (*.mp4 *.avi *.mkv *.mov *.webm *.m4v);;"
               "ROS bags (*.bag *.db3 *.mcap);;Sessions (*.json);;Descriptors (*.npz);;All files (*)")


class MainWindow(QMainWindow):
    mapReady = Signal()          # a run (or a parameter change) produced the map now shown
    runFailed = Signal(str)
    runCancelled = Signal()

    def __init__(self, settings: Optional[QSettings] = None, cache_root: Optional[str] = None,
                 describe_options: Optional[dict] = None, interactive: bool = True) -> None:
        super().__init__()
        self.settings = settings if settings is not None else QSettings(APP_NAME, APP_NAME)
        self.defaults = _default_settings()
        self.cache_root = cache_root
        self.describe_options = dict(describe_options or {})
        self.interactive = interactive
        self.doc = Document(self)
        self.files = RecordingFiles(journaling=interactive)  # session, autosave, journal (gui.model)
        self.frames = FrameCache()
        self.undo_stack = QUndoStack(self)
        self.doc.history = QtHistory(self.undo_stack, self.doc)  # the model's commands, on Qt's stack
        self.queue = ReviewQueue(self.doc)
        self.doc.preparers["layout"] = path_layout  # the graph view's layout, made with each re-map
        self.shortcuts = shortcut_table(self.defaults["shortcuts"])
        self.runner = RunController(self)
        self.remapper = Worker(self)           # build_map on a parameter change, off the UI thread
        self.similarity_worker = Worker(self)  # the similarity matrix, off the UI thread
        self.advance_after_decision = bool(self.defaults["ui"].get("advance_after_decision", True))
        self._pending_decisions: Optional[dict] = None
        self._preparing_run: Optional[FinishedRun] = None  # a finished run whose map is being prepared
        self._pending_view: dict = {}
        self._extra_dirty = False     # changes outside the undo stack (poses loaded)
        self._defaults: dict = {}
        self._last_error = ""

        self._build_views()
        self._build_actions()
        self._build_menus()
        self._build_status_bar()
        self._connect()
        self._update_title()
        self._update_actions()
        bad = bad_overrides(self.defaults["shortcuts"])
        if bad:
            self.statusBar().showMessage(f"Settings: shortcut entries ignored (unknown or fixed): {', '.join(bad)}",
                                         10000)

        app = QApplication.instance()
        if app is not None:  # the thread must end before Qt does, whatever closes the app
            app.aboutToQuit.connect(self.runner.stop)
            app.aboutToQuit.connect(self.remapper.stop)
            app.aboutToQuit.connect(self.similarity_worker.stop)
        self.autosave_timer = QTimer(self)
        self.autosave_timer.setInterval(int(1000 * self.defaults["ui"].get("autosave_seconds", 30)))
        self.autosave_timer.timeout.connect(self.autosave)
        self.autosave_timer.start()
        self.setAcceptDrops(True)
        self.setWindowIcon(_app_icon())
        ui = self.defaults["ui"]
        self.resize(int(ui.get("window_width", 1500)), int(ui.get("window_height", 950)))
        geometry = self.settings.value("window/geometry")
        if geometry is not None and interactive:
            self.restoreGeometry(geometry)
        fit_to_screen(self)   # the default size, or one saved on a bigger screen, fits this one

    # ==== construction ==============================================================
    def _build_views(self) -> None:
        self.frame_viewer = FrameViewer(self.doc, self.frames)
        self.graph_view = GraphView(self.doc)
        self.similarity_view = SimilarityView(self.doc)
        self.loop_table = LoopTable(self.doc)
        self.pair_view = PairView(self.doc, self.frames)
        self.node_panel = NodePanel(self.doc)
        self.params_panel = ParamsPanel()
        self._apply_default_settings()
        self.eval_panel = EvalPanel(self.doc)

        self.tabs = QTabWidget()
        self.tabs.addTab(self.graph_view, "Graph")
        self.tabs.addTab(self.similarity_view, "Similarity matrix")
        # Left: what is looked at (the frame, the map, the node); right: the review queue
        # above the pair view, each as wide as the column (gui.window_layout).
        self.bottom_splitter = QSplitter(Qt.Vertical)
        self.bottom_splitter.addWidget(self.loop_table)
        self.bottom_splitter.addWidget(self.pair_view)
        self.bottom_splitter.setSizes([480, 420])
        self.left_splitter = QSplitter(Qt.Vertical)
        for widget, stretch in ((self.frame_viewer, 3), (self.tabs, 3), (self.node_panel, 1)):
            self.left_splitter.addWidget(widget)
            self.left_splitter.setStretchFactor(self.left_splitter.count() - 1, stretch)
        self.main_splitter = QSplitter(Qt.Horizontal)
        self.main_splitter.addWidget(self.left_splitter)
        self.main_splitter.addWidget(self.bottom_splitter)
        self.main_splitter.setSizes([620, 880])
        self.main_splitter.setChildrenCollapsible(False)
        self.main_splitter.setStretchFactor(0, 2)
        self.main_splitter.setStretchFactor(1, 3)
        self.setCentralWidget(self.main_splitter)

        self.params_dock = QDockWidget("Parameters", self)
        self.params_dock.setObjectName("params_dock")
        self.params_dock.setWidget(self.params_panel)
        self.addDockWidget(Qt.LeftDockWidgetArea, self.params_dock)
        self.eval_dock = QDockWidget("Evaluation", self)
        self.eval_dock.setObjectName("eval_dock")
        self.eval_dock.setWidget(self.eval_panel)
        self.addDockWidget(Qt.LeftDockWidgetArea, self.eval_dock)
        self.splitDockWidget(self.params_dock, self.eval_dock, Qt.Vertical)
        self.resizeDocks([self.params_dock], [250], Qt.Horizontal)

    def _action(self, text: str, slot, key: Optional[str] = None, tip: str = "") -> QAction:
        """A menu action; ``key`` names its entry in the shortcut table (gui.model.keys)."""
        action = QAction(text, self)
        if key is not None:
            self._set_keys(action, key)
        if tip:
            action.setStatusTip(tip)
            action.setToolTip(tip)
        action.triggered.connect(lambda checked=False: slot())
        self.addAction(action)  # shortcuts work even with the menu bar hidden
        return action

    def _set_keys(self, action: QAction, key: str) -> None:
        keys = next(s.keys for s in self.shortcuts if s.action == key)
        action.setShortcuts([QKeySequence(k) for k in keys])
        self.action_of_key[key] = action

    def _build_actions(self) -> None:
        A = self._action
        self.action_of_key: dict[str, QAction] = {}
        self.open_action = A("&Open…", self.open_dialog, "open",
                             "Open a video, a ROS bag, a folder of images, a session or a descriptors .npz")
        self.open_folder_action = A("Open &folder or ROS2 bag…", self.open_folder_dialog, None,
                                    "Open a folder of panoramas or a ROS2 bag directory")
        self.poses_action = A("Load &poses…", self.load_poses_dialog, None,
                              "Load ground-truth poses (CSV t,x,y[,yaw] or a bag topic) for evaluation")
        self.save_action = A("&Save session", self.save_session, "save",
                             "Save decisions and parameters next to the recording")
        self.save_as_action = A("Save session &as…", self.save_session_as, "save_as")
        self.export_action = A("&Export corrected graph (GraphML)…", self.export_graphml_dialog, "export",
                               "Write the corrected map: rejected loops left out, confirmed and manual kept")
        self.export_png_action = A("Export graph &picture (PNG)…", self.export_png_dialog, None,
                                   "Save a picture of the graph view")
        self.export_plot_action = A("Export evaluation &plot (PNG)…", self.export_plot_dialog, None,
                                    "Map and similarity matrix with ground-truth colours")
        self.quit_action = A("&Quit", self.close, "quit")

        self.undo_action = self.undo_stack.createUndoAction(self, "&Undo")
        self._set_keys(self.undo_action, "undo")
        self.redo_action = self.undo_stack.createRedoAction(self, "&Redo")
        self._set_keys(self.redo_action, "redo")
        self.addAction(self.undo_action)
        self.addAction(self.redo_action)
        self.label_action = A("Name this &place…", self.name_place_dialog, "name_place",
                              "Give the current node a place name")

        self.confirm_action = A("&Confirm selected loops", lambda: self.decide("confirmed"), "confirm",
                                "Same place: keep the selected loops")
        self.reject_action = A("&Reject selected loops", lambda: self.decide("rejected"), "reject",
                               "Different places: drop the selected loops")
        self.reset_action = A("Rese&t selected loops", lambda: self.decide("auto"), "reset",
                              "Back to undecided")
        self.next_undecided_action = A("Next &undecided loop", self.next_undecided, "next_undecided",
                                       "Select the next loop nobody has decided on yet")
        self.next_action = A("&Next loop", lambda: self.loop_table.step(1), "next")
        self.prev_action = A("&Previous loop", lambda: self.loop_table.step(-1), "previous")
        self.focus_queue_action = A("&Go to the review queue", self.focus_queue, "focus_queue",
                                    "Move the keyboard to the review queue (about 40 Tabs from the parameters)")
        self.reject_below_action = A("Reject all &below this one", self.reject_below, "reject_below",
                                     "Reject every undecided loop whose evidence is below the selected loop's")
        self.manual_action = A("&Add manual loop…", self.manual_loop_dialog, "manual_loop",
                               "Join two nodes that are the same place")
        self.remove_action = A("Re&move manual loop", self.remove_selected_manual, "remove_manual")
        self.advance_action = QAction("Advance after a decision", self, checkable=True,
                                      checked=self.advance_after_decision)
        self.advance_action.toggled.connect(lambda on: setattr(self, "advance_after_decision", on))

        self.run_action = A("&Run", self.start_run, "run", "Describe the recording and build the map")
        self.cancel_action = A("&Cancel run", self.cancel_run, "cancel_run", "Stop the run; the current map is kept")
        self.shortcuts_action = A("&Keyboard shortcuts", self.show_shortcuts, "shortcuts")
        self.about_action = A("&About panotopo", self.show_about)

    def _build_menus(self) -> None:
        bar = self.menuBar()
        m = bar.addMenu("&File")
        for a in (self.open_action, self.open_folder_action):
            m.addAction(a)
        self.recent_menu = m.addMenu("Open &recent")
        m.addSeparator()
        m.addAction(self.poses_action)
        m.addSeparator()
        for a in (self.save_action, self.save_as_action):
            m.addAction(a)
        m.addSeparator()
        for a in (self.export_action, self.export_png_action, self.export_plot_action):
            m.addAction(a)
        m.addSeparator()
        m.addAction(self.quit_action)
        m = bar.addMenu("&Edit")
        for a in (self.undo_action, self.redo_action):
            m.addAction(a)
        m.addSeparator()
        m.addAction(self.label_action)
        m = bar.addMenu("&Loops")
        for a in (self.confirm_action, self.reject_action, self.reset_action):
            m.addAction(a)
        m.addSeparator()
        for a in (self.next_undecided_action, self.next_action, self.prev_action, self.focus_queue_action):
            m.addAction(a)
        m.addSeparator()
        m.addAction(self.reject_below_action)
        m.addSeparator()
        for a in (self.manual_action, self.remove_action):
            m.addAction(a)
        m.addSeparator()
        m.addAction(self.advance_action)
        m = bar.addMenu("&Run")
        m.addAction(self.run_action)
        m.addAction(self.cancel_action)
        m = bar.addMenu("&View")
        m.addAction(self.params_dock.toggleViewAction())
        m.addAction(self.eval_dock.toggleViewAction())
        m = bar.addMenu("&Help")
        m.addAction(self.shortcuts_action)
        m.addAction(self.about_action)
        self._rebuild_recent_menu()

    def _build_status_bar(self) -> None:
        status = self.statusBar()
        self.summary_label = QLabel()
        self.summary_label.setToolTip("Nodes and loops of the current map")
        self.progress_bar = QProgressBar()
        self.progress_bar.setMaximumWidth(260)
        self.progress_bar.setTextVisible(True)
        self.eta_label = QLabel()
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setToolTip("Stop the run (Esc); the current map and decisions are kept")
        self.cancel_button.clicked.connect(self.cancel_run)
        # Shown for as long as decisions are not journaled (issue 43, defect 14): not only a log line.
        self.journal_label = QLabel()
        self.journal_label.setStyleSheet("color: #c0392b; font-weight: bold")
        self.journal_label.setVisible(False)
        status.addPermanentWidget(self.journal_label)
        status.addPermanentWidget(self.summary_label)
        status.addPermanentWidget(self.progress_bar)
        status.addPermanentWidget(self.eta_label)
        status.addPermanentWidget(self.cancel_button)
        self._show_progress(False)
        status.showMessage("Open a recording to start (File ▸ Open, or drop a file here)")

    def _connect(self) -> None:
        # Bound methods, not lambdas: Qt drops these connections when the window dies.
        self.undo_stack.cleanChanged.connect(self._update_title)
        self.undo_stack.indexChanged.connect(self._update_actions)
        self.undo_stack.indexChanged.connect(self._undo_moved)
        self.runner.progress.connect(self._on_progress)
        self.runner.finished.connect(self._on_run_finished)
        self.runner.failed.connect(self._on_run_failed)
        self.runner.cancelled.connect(self._on_run_cancelled)

        self.frame_viewer.frameChanged.connect(self._frame_changed)
        self.graph_view.nodeClicked.connect(self.show_node)
        self.graph_view.loopClicked.connect(self.select_loop)
        self.graph_view.manualLoopRequested.connect(self._ctrl_click_loop)
        self.similarity_view.pairClicked.connect(self.select_pair)
        self.node_panel.labelEdited.connect(self.set_label)
        self.node_panel.loopActivated.connect(self.select_loop)
        self.node_panel.addLoopRequested.connect(lambda k: self.manual_loop_dialog(k))
        self.loop_table.loopSelected.connect(self._loop_selected)
        self.pair_view.decide.connect(self.decide_pair)
        self.pair_view.addManual.connect(self.add_manual_loop)
        self.pair_view.removeManual.connect(self.remove_manual_loop)
        self.params_panel.paramsEdited.connect(self._params_edited)
        self.params_panel.calibrateRequested.connect(self.calibrate_thresholds)
        self.params_panel.runRequested.connect(self.start_run)
        self.params_panel.describeEdited.connect(
            lambda: self.statusBar().showMessage("Descriptor settings changed: press Run (F5) to describe again", 8000))
        self.doc.mapReplaced.connect(self._sync_current_node)
        self.doc.mapReplaced.connect(self._update_summary)
        self.doc.loopsChanged.connect(self._update_summary)
        self.doc.mapReplaced.connect(self._update_actions)
        self.doc.loopsChanged.connect(self._update_actions)
        self.doc.mapReplaced.connect(self._request_similarity)
        self.doc.journalFailed.connect(self._journal_failed)
        self.tabs.currentChanged.connect(self._request_similarity)
        # Ctrl+Z in the place-name field: the app's undo once the name is applied (defect 7).
        self.node_panel.name.installEventFilter(self)
        app = QApplication.instance()
        self._watching_focus = app is not None
        if app is not None:
            app.focusChanged.connect(self._focus_changed)

    def _apply_default_settings(self) -> None:
        """Start from resources/default_settings.json (map parameters, descriptor, interval, distance)."""
        known = set(MapParams.__dataclass_fields__)
        try:
            params = MapParams(**{k: v for k, v in self.defaults["map"].items() if k in known})
        except TypeError:
            params = MapParams()
        if params.method not in __import__("engine.params", fromlist=["METHODS"]).METHODS:
            params = MapParams()
        self.doc.params = params
        self._start_params = params   # what a newly opened recording starts from
        self.params_panel.set_params(params, {})
        describe = self.defaults["describe"]
        self.params_panel.set_describe(str(describe.get("descriptor", self.params_panel.descriptor_name())),
                                       float(describe.get("interval", 1.0)))
        self.doc.dist_th = float(self.defaults["eval"].get("dist_th", 1.0))

    # ==== opening =====================================================================
    def open_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open", self._last_dir(), OPEN_FILTER)
        if path:
            self.open_path(path)

    def open_folder_dialog(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "Open folder or ROS2 bag", self._last_dir())
        if path:
            self.open_path(path)

    def open_path(self, path: str, topic: Optional[str] = None, pose_topic: Optional[str] = None,
                  run: bool = True) -> bool:
        """Open a recording, a bag, a folder, a session or a descriptors .npz (and run)."""
        if not self.maybe_save():
            return False
        p = Path(path).expanduser()
        try:
            if p.is_file() and is_session_file(p):
                ok = self._open_session(p, run=run)
            else:
                ok = self._open_input(p, topic, pose_topic, run=run)
        except InputError as exc:
            self.error(str(exc))
            return False
        if ok:
            self._add_recent(str(p))
        return ok

    def _open_input(self, p: Path, topic: Optional[str], pose_topic: Optional[str], run: bool,
                    session: Optional[Session] = None, session_file: Optional[Path] = None) -> bool:
        from engine.pipeline import DescribeSettings, is_descriptor_file

        if not p.exists():
            raise InputError(f"{p}: no such file or directory")
        source, descriptors_file = None, is_descriptor_file(p)
        if descriptors_file:
            from engine.descriptors.base import Descriptors

            descs = Descriptors.load(p)  # validate now: a bad file fails here, not in the worker
            source = self._source_for_descriptors(descs)
            settings = DescribeSettings(descriptor=descs.meta.get("descriptor", self.params_panel.descriptor_name()),
                                        interval=float(descs.meta.get("interval", 1.0) or 1.0),
                                        shift=bool(descs.meta.get("shift", True)))
        else:
            if session is None and self._is_bag(p) and topic is None:
                chosen = self._choose_bag_topics(p)
                if chosen is None:
                    return False
                topic, pose_topic = chosen
            source = self._open_recording_in_background(p, topic)
            if session is not None and session.describe:
                settings = _describe_settings(session.describe, self.describe_options)
            else:
                params = session.map_params() if session else self.params_panel.params()
                descriptor = self.params_panel.descriptor_name()
                settings = DescribeSettings(descriptor=descriptor,
                                            interval=self.params_panel.interval_value(), topic=topic,
                                            shift=params.uses_shift,
                                            options=self._panel_options(self.describe_options, descriptor))

        try:
            self.files.attach(p)
        except JournalLocked as exc:
            self.error(f"{p.name} is open in another panotopo window ({exc.holder}): close it there first")
            return False

        # A new document: nothing of the previous one survives.
        self.runner.stop()
        self.remapper.stop()
        self.similarity_worker.stop()
        self._preparing_run = None
        self.undo_stack.clear()
        self._extra_dirty = False
        self.doc.clear_map()
        self.doc.set_poses(None, None)
        self.doc.session_path = None
        self.doc.journal = self.files.journal
        self.doc.describe_settings = settings
        # A new recording starts from the starting parameters (issue 43, defect 3): never
        # from what was set on the recording open before.
        self.doc.params = session.map_params() if session else self._start_params
        self._pending_decisions = None
        self._pending_view = {}
        self.doc.set_source(p, source)
        self.doc.mapReplaced.emit()  # views clear
        self.select_pair_key(None)   # nothing of the previous recording stays selected (defect 5)
        self.params_panel.set_describe(settings.descriptor, settings.interval)
        self._load_initial_poses(p, session, pose_topic)
        self._restore_saved_work(p, session, session_file)
        self.params_panel.set_params(self.doc.params, {})   # unset thresholds: "auto" until the map is built
        self._show_journal_state()
        self._update_title()
        self.statusBar().showMessage(f"Opened {p.name}", 5000)
        if run:
            self.start_run()
        return True

    # ==== saved and unsaved work (gui.model.recording_files) ===================================
    def _restore_saved_work(self, p: Path, session: Optional[Session], session_file: Optional[Path]) -> None:
        """The recording's saved session, whichever file was opened, and unsaved work only if
        the user says so (issue 43, defect 17): "No" restores nothing and drops it."""
        saved_path = session_file if session is not None else self.files.saved_session(p)
        saved = session
        if saved is None and saved_path is not None:
            try:
                saved = Session.load(saved_path)
            except InputError as exc:
                self.warn(str(exc))
                saved_path = None
        unsaved, warnings = self.files.unsaved(p, saved_path)
        for text in warnings:
            self.warn(text)
        if unsaved:
            if self._ask_yes_no("Restore unsaved work",
                                f"Unsaved work on {p.name} was found ({unsaved.describe()}). Restore it?"):
                pass
            else:
                if self.interactive:
                    self.files.discard(p)   # declined: it must not come back on the next open
                unsaved = Unsaved()
        if saved is None and not unsaved:
            return
        restored = self.files.restore(unsaved, saved)
        if restored.session is not None and restored.session is not session:
            self.doc.params = restored.session.map_params()
        self._pending_decisions = restored.decisions
        self._pending_view = dict(restored.session.view) if restored.session is not None else {}
        self.doc.session_path = saved_path
        if unsaved:
            self._extra_dirty = True
            self.statusBar().showMessage(f"Unsaved work restored ({unsaved.describe()}; not saved yet)", 10000)
        elif saved_path is not None:
            self.statusBar().showMessage(f"Decisions restored from {saved_path.name}", 8000)
        if restored.skipped:
            self.warn(f"{restored.skipped} journal records of {p.name} could not be read and were skipped; "
                      "the others were restored")

    def _show_journal_state(self) -> None:
        problem = self.files.problem
        self.journal_label.setText("Not journaled" if problem else "")
        self.journal_label.setToolTip(problem)
        self.journal_label.setVisible(bool(problem))
        if problem:
            self.warn(problem)

    def _journal_failed(self, message: str) -> None:
        self.files.journal_failed(message)
        self._show_journal_state()

    def _open_session(self, path: Path, run: bool = True) -> bool:
        session = Session.load(path)
        ok = self._open_input(Path(session.input_path), session.describe.get("topic"), None, run=run,
                              session=session, session_file=path)
        if ok:
            self.doc.session_path = path
            self._update_title()
        return ok

    def _open_recording_in_background(self, p: Path, topic: Optional[str]):
        """Open and index a recording off the UI thread (a long video or a big bag takes a while)."""
        from engine.sources import open_recording

        from .background import call_in_background

        def open_and_index():
            source = open_recording(p, topic=topic)
            source.stamps()  # the one pass over the recording; cached by the source
            return source

        return call_in_background(self, f"Reading {p.name}…", open_and_index)

    def _source_for_descriptors(self, descs):
        """The recording a descriptors file was made from, if it is still there (for the viewer)."""
        src = descs.meta.get("source")
        if not src or not Path(src).exists():
            return None
        try:
            from engine.sources import open_recording

            return open_recording(Path(src), topic=descs.meta.get("topic"))
        except InputError:
            return None

    @staticmethod
    def _is_bag(p: Path) -> bool:
        if p.is_file():
            return p.suffix.lower() in (".bag", ".db3", ".mcap")
        from engine.sources.rosbag import is_ros2_bag_dir

        return p.is_dir() and is_ros2_bag_dir(p)

    def _choose_bag_topics(self, p: Path) -> Optional[tuple[Optional[str], Optional[str]]]:
        from engine.sources import list_image_topics, list_pose_topics

        from .open_dialog import BagTopicDialog, default_topics

        images = list_image_topics(p)
        if not images:
            raise InputError(f"{p}: the bag has no image topics")
        poses = list_pose_topics(p)
        if not self.interactive or (len(images) == 1 and not poses):
            return default_topics(images, poses)
        dialog = BagTopicDialog(str(p), images, poses, self)
        if dialog.exec() != BagTopicDialog.Accepted:
            return None
        return dialog.chosen()

    def _load_initial_poses(self, p: Path, session: Optional[Session], pose_topic: Optional[str]) -> None:
        from engine.sources import read_poses

        try:
            if session is not None and session.poses_path:
                self.doc.set_poses(read_poses(session.poses_path, session.poses_topic),
                                   session.poses_path, session.poses_topic)
            elif pose_topic:
                self.doc.set_poses(read_poses(p, pose_topic), str(p), pose_topic)
            else:
                base = p if p.is_dir() else p.parent
                for candidate in (p.with_name(p.stem + ".poses.csv"), p.parent / "poses.csv", base / "poses.csv"):
                    if candidate.is_file():
                        self.doc.set_poses(read_poses(candidate), str(candidate))
                        self.statusBar().showMessage(f"Loaded ground truth from {candidate.name}", 5000)
                        break
        except InputError as exc:
            self.warn(f"Ground-truth poses not loaded: {exc}")

    # ==== poses ==========================================================================
    def load_poses_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load ground-truth poses", self._last_dir(),
                                              "Poses (*.csv *.bag *.db3 *.mcap);;All files (*)")
        if path:
            self.load_poses(path)

    def load_poses(self, path: str, topic: Optional[str] = None) -> bool:
        from engine.sources import list_pose_topics, read_poses

        p = Path(path)
        try:
            if topic is None and (self._is_bag(p)):
                topics = [t for t, _m, _c in list_pose_topics(p)]
                if not topics:
                    raise InputError(f"{p}: the bag has no pose topics")
                if len(topics) > 1 and self.interactive:
                    topic, ok = QInputDialog.getItem(self, "Pose topic", "Ground-truth pose topic:", topics, 0, False)
                    if not ok:
                        return False
                else:
                    topic = topics[0]
            poses = read_poses(p, topic)
        except InputError as exc:
            self.error(str(exc))
            return False
        self.doc.set_poses(poses, str(p), topic)
        self._extra_dirty = True
        self._update_title()
        self.statusBar().showMessage(f"Ground truth loaded: {len(poses)} poses from {p.name}", 5000)
        return True

    # ==== running =========================================================================
    def start_run(self) -> None:
        from engine.pipeline import DescribeSettings

        if self.doc.input_path is None:
            self.statusBar().showMessage("Open a recording first", 5000)
            return
        old = self.doc.describe_settings or DescribeSettings()
        descriptor = self.params_panel.descriptor_name()
        interval = self.params_panel.interval_value()
        if self.doc.descs is not None and str(self.doc.input_path).endswith(".npz"):
            descriptor, interval = old.descriptor, old.interval  # a descriptors file is what it is
        options = self._panel_options(old.options if descriptor == old.descriptor else self.describe_options,
                                      descriptor)
        settings = DescribeSettings(descriptor=descriptor, interval=interval, topic=old.topic,
                                    shift=self.doc.params.uses_shift, options=options)
        self._start(settings)

    def _panel_options(self, options: dict, descriptor: str) -> dict:
        """The user's describe ``options`` with the panel's photometric choice: named when
        chosen, left to the method (``engine.pipeline.method_settings``) when not."""
        out = {k: v for k, v in options.items() if k != "photometric"}
        choice = self.params_panel.photometric_choice()
        if choice is not None and photometric_applies(descriptor):
            out["photometric"] = choice
        return out

    def _start(self, settings) -> None:
        from engine.descriptors.cache import DescriptorCache

        if self.runner.running:
            self.runner.cancel()   # the new run waits for the old one to stop at its next check
        self._preparing_run = None  # a new run supersedes the map being prepared
        self._show_progress(True)
        self._progress_stage = ""
        self._stage_started = time.monotonic()
        self.progress_bar.setRange(0, 0)
        self.progress_bar.setFormat("starting…")
        self.eta_label.setText("")
        job = RunJob(Path(self.doc.input_path), settings, self.doc.params, DescriptorCache(self.cache_root))
        self.statusBar().showMessage("Running the engine…")
        self.runner.start(job)
        self._update_actions()

    def cancel_run(self) -> None:
        if self.runner.running:
            self.runner.cancel()
            self.cancel_button.setEnabled(False)
            self.statusBar().showMessage("Cancelling…")

    def _on_progress(self, done: int, total: int, stage: str) -> None:
        now = time.monotonic()
        if stage != self._progress_stage:
            self._progress_stage, self._stage_started = stage, now
        if total > 0:
            self.progress_bar.setRange(0, total)
            self.progress_bar.setValue(min(done, total))
            self.progress_bar.setFormat(f"{stage}: {done}/{total}")
            elapsed = now - self._stage_started
            if done > 0 and elapsed > 0.5:
                self.eta_label.setText(f"ETA {_duration(elapsed * (total - done) / done)}")
        else:
            self.progress_bar.setRange(0, 0)
            self.progress_bar.setFormat(stage)

    def _on_run_finished(self, result: FinishedRun) -> None:
        """The run's map is prepared off the UI thread too (decisions applied, rows, layout)."""
        # Decisions survive a re-run: the current ones, or those of the session just opened.
        pending, self._pending_decisions = self._pending_decisions, None
        self._preparing_run = result
        self.progress_bar.setRange(0, 0)
        self.progress_bar.setFormat("preparing the map")
        job = self.doc.remap_job(lambda: result.topomap, pending)
        self.remapper.submit(job, lambda prepared: self._run_prepared(result, pending, prepared),
                             lambda exc: self._run_prepare_failed(result, exc))

    def _run_prepare_failed(self, result: FinishedRun, exc: BaseException) -> None:
        if self._preparing_run is result:
            self._preparing_run = None
            self._on_run_failed(f"unexpected error: {exc.__class__.__name__}: {exc}")

    def _run_prepared(self, result: FinishedRun, pending, prepared) -> None:
        from engine.pipeline import descriptor_defaults

        if self._preparing_run is not result:
            return  # another run or another recording came in meanwhile
        if pending is None and not self.doc.is_current(prepared):  # decided on the old map meanwhile
            self._on_run_finished(result)  # prepare again, with those decisions
            return
        self._preparing_run = None
        self._show_progress(False)
        self.doc.describe_settings = result.job.settings
        self._defaults = descriptor_defaults(result.descs)
        self._set_known_shifts(result.descs)
        self.doc.install(prepared, result.descs)
        if needs_remap(result.job.params, self.doc.params):
            # The user changed a map parameter while the run was going: honour it (off the UI thread).
            self._remap(self.doc.params)
        elif result.job.params != self.doc.params:
            # ... or the method, to one that needs other descriptors: describe again, or map a .npz.
            self._apply_params(result.job.params, self.doc.params)
        self.params_panel.set_describe(result.job.settings.descriptor, result.job.settings.interval)
        self.params_panel.set_photometric(result.job.settings.options.get("photometric"))
        self.params_panel.set_params(self.doc.params, self._used_defaults())
        self._restore_view()
        self.statusBar().showMessage(
            f"Map built in {result.seconds:.1f} s: {self.doc.node_count()} nodes, "
            f"{len(self.doc.loop_rows())} loop candidates", 10000)
        self._update_actions()
        if self.is_modified():
            self.autosave()
        _settle_garbage_collector()
        self.mapReady.emit()

    def _on_run_failed(self, message: str) -> None:
        self._show_progress(False)
        self._update_actions()
        self.error(message)
        self.runFailed.emit(message)

    def _on_run_cancelled(self) -> None:
        self._show_progress(False)
        self._update_actions()
        self.statusBar().showMessage("Run cancelled; the current map and decisions are unchanged", 8000)
        self.runCancelled.emit()

    def _show_progress(self, on: bool) -> None:
        for w in (self.progress_bar, self.eta_label, self.cancel_button):
            w.setVisible(on)
        self.cancel_button.setEnabled(on)

    def _used_defaults(self, built: bool = True) -> dict:
        """What an unset threshold stands for, where that is known
        (``gui.model.run_plan.known_thresholds``); the others read "auto". ``built``: the map
        shown was built with the parameters of now (else its meta says nothing about them)."""
        from .model.run_plan import known_thresholds

        topomap = self.doc.topomap
        meta = topomap.meta if topomap is not None and built else None
        return known_thresholds(self.doc.params, meta, self._defaults)

    def _set_known_shifts(self, descs) -> None:
        self.frames.known_shifts = ({int(f): int(s) for f, s in zip(descs.frames, descs.shifts)}
                                    if descs.meta.get("shift", True) else {})

    # ==== parameters ======================================================================
    def _params_edited(self, field: str, new: MapParams) -> None:
        old = self.doc.params
        if new == old:
            return
        self.undo_stack.push(ChangeParams(self._apply_params, old, new, field))

    def calibrate_thresholds(self) -> None:
        """Node and loop thresholds of the paper's methods from this recording (one undo step)."""
        from engine.calibrate import paper_thresholds

        if self.doc.descs is None:
            self.statusBar().showMessage("Run the recording first: thresholds come from its descriptors", 5000)
            return
        old = self.doc.params
        new = replace(old, **paper_thresholds(self.doc.descs.vectors, old.neighbor_node_num))
        if new != old:
            self.undo_stack.push(ChangeParams(self._apply_params, old, new, "thresholds"))

    def _apply_params(self, _old: MapParams, new: MapParams) -> None:
        """Rebuild the map with ``new`` (undo/redo and the panel both land here)."""
        from engine.pipeline import DescribeSettings, descriptors_fit, method_settings

        self.doc.params = new
        if self.doc.input_path is None:   # set before any recording is open: where recordings start
            self._start_params = new
        self.params_panel.set_params(new, self._used_defaults(built=False))
        descs = self.doc.descs
        if descs is None or self._preparing_run is not None:
            return  # the run's map is on its way; it is rebuilt with ``new`` when it lands
        # What the descriptors were described with (their meta) against what ``new`` asks for
        # on top of the user's own describe settings (panorama shift, a method's describe options).
        wanted = method_settings(new, self.doc.describe_settings or DescribeSettings())
        if not descriptors_fit(descs, wanted):
            if not str(self.doc.input_path).endswith(".npz"):
                self.start_run()  # describe again (cached when done before)
                return
            if new.uses_shift != bool(descs.meta.get("shift", True)):
                self.warn(f"Method '{new.method}' needs {'shifted' if new.uses_shift else 'unshifted'} "
                          "descriptors, which this descriptors file does not have")
                return
            # Only a describe option differs: a descriptors file is what it is; map it.
        self._remap(new)

    def _remap(self, params: MapParams) -> None:
        """Build and prepare the map with ``params`` off the UI thread; the newest request wins."""
        from engine.pipeline import build_map

        descs, source = self.doc.descs, str(self.doc.input_path)
        self.statusBar().showMessage("Rebuilding the map…")
        job = self.doc.remap_job(lambda: build_map(descs, params, source=source))
        self.remapper.submit(job, lambda prepared: self._remapped(descs, params, prepared),
                             lambda exc: self._remap_failed(descs, params, exc))

    def _remap_failed(self, descs, params: MapParams, exc: BaseException) -> None:
        if self.doc.descs is not descs or self.doc.params != params:
            return
        if isinstance(exc, InputError):
            self.warn(str(exc))
        else:
            self.error(f"unexpected error: {exc.__class__.__name__}: {exc}")

    def _remapped(self, descs, params: MapParams, prepared) -> None:
        if self.doc.descs is not descs or self.doc.params != params:
            return  # a new run or another parameter change came in meanwhile
        if not self.doc.is_current(prepared):
            self._remap(params)  # decided (or loaded poses) while it built: build with those
            return
        self.doc.install(prepared)
        self.params_panel.set_params(params, self._used_defaults())
        self.statusBar().showMessage(
            f"{self.doc.node_count()} nodes, {len(self.doc.loop_rows())} loops with the new parameters", 5000)
        self.mapReady.emit()

    # ==== curation =========================================================================
    def selected_key(self) -> Optional[LoopKey]:
        return self.loop_table.selected_key() or self.pair_view.key

    def decide(self, status: str) -> None:
        """Confirm, reject or reset the loops selected in the table (one undo step), nothing else.

        A decision applies only to rows the user sees selected; after it the selection moves
        to the row below, and stays on the last row (no wrap: issue 14, defect 1).
        """
        keys = self.loop_table.selected_keys()
        if not keys:
            self.statusBar().showMessage("Select a loop in the table first", 4000)
            return
        self._decide_keys(keys, status, order=self.loop_table.visible_keys())

    def decide_pair(self, status: str) -> None:
        """A decision button of the pair view: the loop shown there."""
        if self.pair_view.key is not None:
            self._decide_keys([self.pair_view.key], status, order=self.loop_table.visible_keys())

    def _decide_keys(self, keys: list, status: str, order: list) -> None:
        manual = [k for k in keys if self.doc.status_of(k) == "manual"]
        if len(manual) == len(keys):
            self.statusBar().showMessage("A manual loop has no decision to change: remove it instead (Delete)", 5000)
            return
        self.queue.select(keys)
        self.queue.advance_after_decision = self.advance_after_decision
        changed = self.queue.decide(status, order=order)
        self.loop_table.select_keys(self.queue.selected)
        if len(keys) > 1:
            self.statusBar().showMessage(f"{edits.verb(status)}: {changed} of {len(keys)} selected loops "
                                         "changed (one undo step)", 5000)

    def next_undecided(self) -> None:
        """Select the next loop nobody has decided on (in the order shown; wraps to the top)."""
        current = self.loop_table.selected_key()
        key = self.queue.next_undecided(after=current, order=self.loop_table.visible_keys())
        if key is None:  # none shown: the filter may hide them
            key = self.queue.next_undecided(after=current)
        if key is None:
            self.statusBar().showMessage("Every loop is decided", 5000)
            return
        self.loop_table.select_key(key)

    def focus_queue(self) -> None:
        """The keyboard to the review queue, on its current row (the first when none is)."""
        self.loop_table.view.setFocus(Qt.ShortcutFocusReason)
        if self.loop_table.selected_key() is None:
            self.select_first_loop()

    def reject_below(self) -> None:
        """Reject every undecided loop ranked below the selected one (one undo step)."""
        key = self.loop_table.selected_key()
        if key is None:
            self.statusBar().showMessage("Select the weakest loop you judged good first", 5000)
            return
        n = self.queue.reject_below(self.queue.evidence_of(key))
        self.loop_table.select_key(key)
        self.statusBar().showMessage(f"Rejected {n} undecided loops ranked below the selected one "
                                     "(Ctrl+Z undoes them all)", 8000)

    def add_manual_loop(self, key: LoopKey) -> bool:
        try:
            yaw = pair_yaw(self.doc, self.frames, tuple(key), self.pair_view.match_cache.peek)  # issue 14, 8
            self.doc.push(edits.AddManualLoop(tuple(key), yaw))
        except InputError as exc:
            self.warn(str(exc))
            return False
        self.loop_table.select_key(tuple(key))
        return True

    def _ctrl_click_loop(self, a: int, b: int) -> None:
        """Ctrl+click in the graph: a manual loop from the current node, after a question (defect 10)."""
        if abs(a - b) < 2:
            self.statusBar().showMessage("Neighbouring nodes are already joined by the path", 5000)
            return
        lo, hi = min(a, b), max(a, b)
        if not self._ask_yes_no("Add manual loop", f"Join n{lo} and n{hi} as the same place (a manual loop)?"):
            return
        if self.add_manual_loop(self._key_of_nodes(a, b)):
            self.statusBar().showMessage(f"Manual loop n{lo} ↔ n{hi} added (Ctrl+Z to undo)", 5000)

    def remove_manual_loop(self, key: LoopKey) -> None:
        attrs = self.doc.loop_attrs(key)
        if attrs is None or attrs.get("status") != "manual":
            self.statusBar().showMessage("Only manual loops can be removed; reject a detected loop instead", 5000)
            return
        self.doc.push(edits.RemoveLoop(self.doc, key))

    def remove_selected_manual(self) -> None:
        key = self.selected_key()
        if key is not None:
            self.remove_manual_loop(key)

    def manual_loop_dialog(self, first: Optional[int] = None, second: Optional[int] = None) -> None:
        if not self.doc.has_map:
            return
        if first is None:
            first = self.doc.node_at_or_before(max(self.frame_viewer.current_frame, 0)) or 0
        dialog = ManualLoopDialog(self.doc, first, second, self)
        if dialog.exec() == ManualLoopDialog.Accepted:
            a, b = dialog.nodes()
            self.add_manual_loop(self._key_of_nodes(a, b))

    def name_place_dialog(self) -> None:
        if not self.doc.has_map:
            return
        k = self.doc.node_at_or_before(max(self.frame_viewer.current_frame, 0))
        frame = int(self.doc.node_data(self.doc.node_id(k))["frame"])
        old = self.doc.label_of_frame(frame)
        dialog = QInputDialog(self)
        dialog.setWindowTitle("Name this place")
        dialog.setLabelText(f"Place name of node n{k} (frame {frame}):")
        dialog.setTextValue(old)
        field = dialog.findChild(QLineEdit)
        if field is not None:
            field.setMaxLength(LABEL_MAX)   # enforced where it is typed (issue 43, defect 16)
        if dialog.exec() == QInputDialog.Accepted:
            self.set_label(frame, dialog.textValue().strip())

    def set_label(self, frame: int, label: str) -> None:
        old = self.doc.label_of_frame(frame)
        if len(label) > LABEL_MAX:
            self.warn(f"A place name has at most {LABEL_MAX} characters; this one has {len(label)}")
            return
        if label != old:
            self.doc.push(edits.SetLabel(frame, old, label))

    def _key_of_nodes(self, a: int, b: int) -> LoopKey:
        return self.doc.key_of_nodes(a, b)

    # ==== selection sync ===================================================================
    def select_loop(self, key: LoopKey) -> None:
        if not self.loop_table.select_key(key):
            self.select_pair_key(key)

    def select_pair(self, a: int, b: int) -> None:
        """A pair of nodes clicked in the matrix: its loop, or the pair itself."""
        key = self._key_of_nodes(a, b)
        if self.doc.loop_attrs(key) is not None:
            self.loop_table.select_key(key)
        else:
            self.select_pair_key(key)
            self.statusBar().showMessage(
                f"n{a} ↔ n{b} is not a loop: “Add as manual loop” in the pair view joins them", 6000)

    def select_pair_key(self, key: LoopKey) -> None:
        self.loop_table.select_key(None)
        self.pair_view.show_pair(key)
        self.graph_view.set_selected_loop(key)
        self.similarity_view.set_selected_pair(key)

    def _loop_selected(self, key: Optional[LoopKey]) -> None:
        if key is None:
            return
        self.pair_view.show_pair(key)
        self.graph_view.set_selected_loop(key)
        self.similarity_view.set_selected_pair(key)
        self.frame_viewer.show_frame(key[0])

    def show_node(self, k: int) -> None:
        self.frame_viewer.show_frame(int(self.doc.node_data(self.doc.node_id(k))["frame"]))

    def _sync_current_node(self) -> None:
        self._frame_changed(self.frame_viewer.current_frame)

    def _frame_changed(self, frame: int) -> None:
        k = self.doc.node_at_or_before(frame) if self.doc.has_map else None
        self.graph_view.set_current_node(k)
        if k != self.node_panel.node_index:
            self.node_panel.show_node(k)

    def select_first_loop(self) -> bool:
        """Select the first candidate in the table (if none is selected); False when there is none."""
        rows = self.loop_table.proxy.rowCount()
        if rows and self.loop_table.selected_key() is None:
            self.loop_table.step(1)
        return rows > 0

    # ==== sessions =========================================================================
    def is_modified(self) -> bool:
        return not self.undo_stack.isClean() or self._extra_dirty

    def current_session(self) -> Session:
        settings = self.doc.describe_settings
        decisions = self.doc.decisions() if self.doc.has_map else (self._pending_decisions or {})
        key = self.selected_key()
        frame = self.frame_viewer.current_frame
        view = {"frame": frame if frame >= 0 else None, "tab": self.tabs.currentIndex(),  # -1: no frames shown
                "filter": self.loop_table.filter.currentIndex(),
                "selected": list(key) if key is not None else None}
        return Session(input_path=str(self.doc.input_path), describe=settings.as_dict() if settings else {},
                       params=self.doc.params.as_dict(), decisions=decisions, poses_path=self.doc.poses_path,
                       poses_topic=self.doc.poses_topic, view=view)

    def save_session(self, path: Optional[str] = None) -> bool:
        if self.doc.input_path is None:
            return False
        target = Path(path) if path else (self.doc.session_path or session_path_for(self.doc.input_path))
        try:
            self.files.save(self.current_session(), target)
        except (OSError, InputError) as exc:
            self.error(f"Could not save the session to {target}: {getattr(exc, 'strerror', None) or exc}")
            return False
        self.doc.session_path = target
        self.undo_stack.setClean()
        self._extra_dirty = False
        self._update_title()
        self._add_recent(str(target))
        self.statusBar().showMessage(f"Session saved to {target}", 5000)
        return True

    def save_session_as(self) -> bool:
        if self.doc.input_path is None:
            return False
        start = str(self.doc.session_path or session_path_for(self.doc.input_path))
        path, _ = QFileDialog.getSaveFileName(self, "Save session", start, "Sessions (*.json)")
        return self.save_session(path) if path else False

    def autosave(self) -> None:
        """Write unsaved work to the autosave file (never the user's session file)."""
        if self.doc.input_path is None or not self.is_modified():
            return
        try:
            self.files.autosave(self.current_session())
        except (OSError, InputError) as exc:
            self.statusBar().showMessage(f"Autosave failed: {exc}", 8000)

    def _restore_view(self) -> None:
        view, self._pending_view = self._pending_view, {}
        if not view:
            return
        if isinstance(view.get("tab"), int):
            self.tabs.setCurrentIndex(view["tab"])
        if isinstance(view.get("filter"), int):
            self.loop_table.filter.setCurrentIndex(view["filter"])
        if isinstance(view.get("selected"), list) and len(view["selected"]) == 2:
            self.select_loop(tuple(int(f) for f in view["selected"]))
        if isinstance(view.get("frame"), int) and view["frame"] >= 0:  # after the selection, which moves it
            self.frame_viewer.show_frame(view["frame"])

    def maybe_save(self) -> bool:
        """Ask before unsaved work is dropped; False means stay."""
        if not self.is_modified() or self.doc.input_path is None:
            return True
        answer = QMessageBox.question(
            self, "Unsaved changes",
            f"Save your decisions on {self.doc.input_path.name} before closing it?",
            QMessageBox.Save | QMessageBox.Discard | QMessageBox.Cancel, QMessageBox.Save)
        if answer == QMessageBox.Save:
            return self.save_session()
        if answer == QMessageBox.Discard:
            self.files.discard(self.doc.input_path)  # discarded: they must not come back on the next open
            self.undo_stack.setClean()
            self._extra_dirty = False
            return True
        return False

    # ==== export ===========================================================================
    def export_graphml(self, path: str) -> bool:
        if not self.doc.has_map:
            self.statusBar().showMessage("Nothing to export: run the engine first", 5000)
            return False
        try:
            self.doc.topomap.write_graphml(path, keep_rejected=False)
        except (InputError, OSError) as exc:
            self.error(f"Export failed: {exc}")
            return False
        self.statusBar().showMessage(f"Corrected graph written to {path}", 6000)
        return True

    def export_graphml_dialog(self) -> None:
        if not self.doc.has_map:
            return
        start = str(Path(self.doc.input_path).with_suffix(".graphml"))
        path, _ = QFileDialog.getSaveFileName(self, "Export corrected graph", start, "GraphML (*.graphml)")
        if path:
            self.export_graphml(path)

    def export_graph_png(self, path: str) -> bool:
        ok = self.graph_view.plot.grab().save(path)
        if not ok:
            self.error(f"Could not write {path}")
        return bool(ok)

    def export_png_dialog(self) -> None:
        start = str(Path(self.doc.input_path or "graph").with_suffix(".png"))
        path, _ = QFileDialog.getSaveFileName(self, "Export graph picture", start, "PNG (*.png)")
        if path:
            self.export_graph_png(path)

    def export_plot_dialog(self) -> None:
        if not self.doc.has_map:
            return
        from engine.plots import plot_map

        start = str(Path(self.doc.input_path).with_suffix(".map.png"))
        path, _ = QFileDialog.getSaveFileName(self, "Export evaluation plot", start, "PNG (*.png)")
        if path:
            try:
                plot_map(self.doc.topomap, self.doc.poses, self.doc.evaluation, path)
            except (InputError, OSError) as exc:
                self.error(f"Export failed: {exc}")

    # ==== messages, title, recent files ===================================================
    def error(self, message: str) -> None:
        self._last_error = message
        self.statusBar().showMessage(message, 10000)
        if self.interactive:
            QMessageBox.critical(self, "panotopo", message)
        else:
            print(f"panotopo: {message}", file=sys.stderr)

    def warn(self, message: str) -> None:
        self.statusBar().showMessage(message, 10000)
        if self.interactive:
            QMessageBox.warning(self, "panotopo", message)
        else:
            print(f"panotopo: {message}", file=sys.stderr)

    def _ask_yes_no(self, title: str, text: str) -> bool:
        if not self.interactive:
            return False
        return QMessageBox.question(self, title, text, QMessageBox.Yes | QMessageBox.No,
                                    QMessageBox.Yes) == QMessageBox.Yes

    def _update_title(self, *_args) -> None:
        name = Path(self.doc.input_path).name if self.doc.input_path else "no recording"
        if self.doc.session_path:
            name += f" — {Path(self.doc.session_path).name}"
        self.setWindowTitle(f"{name}[*] — panotopo")
        self.setWindowModified(self.is_modified())

    def _update_summary(self) -> None:
        if not self.doc.has_map:
            self.summary_label.setText("")
            return
        rows = self.doc.loop_rows()
        undecided = self.queue.counts()["undecided"]["undecided"]
        self.summary_label.setText(f"{self.doc.node_count()} nodes · {len(rows)} loops · {undecided} undecided")
        self._update_title()

    def _update_actions(self, *_args) -> None:
        has_map = self.doc.has_map
        running = self.runner.running
        for a in (self.export_action, self.export_png_action, self.export_plot_action, self.manual_action,
                  self.label_action):
            a.setEnabled(has_map)
        self.run_action.setEnabled(self.doc.input_path is not None)
        self.cancel_action.setEnabled(running)
        self.save_action.setEnabled(self.doc.input_path is not None)
        self.save_as_action.setEnabled(self.doc.input_path is not None)
        self._update_title()

    def _last_dir(self) -> str:
        return str(self.settings.value("last_dir", str(Path.home())))

    def recent_files(self) -> list[str]:
        value = self.settings.value("recent", [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def _add_recent(self, path: str) -> None:
        if not self.interactive:  # a screenshot or scripted run must not touch the user's list
            return
        path = str(Path(path).resolve())
        recent = [path] + [r for r in self.recent_files() if r != path]
        self.settings.setValue("recent", recent[:int(self.defaults["ui"].get("max_recent_files", 10))])
        self.settings.setValue("last_dir", str(Path(path).parent))
        self._rebuild_recent_menu()

    def _rebuild_recent_menu(self) -> None:
        self.recent_menu.clear()
        recent = self.recent_files()
        for path in recent:
            action = self.recent_menu.addAction(path)
            action.triggered.connect(lambda checked=False, p=path: self.open_path(p))
        if not recent:
            self.recent_menu.addAction("(none)").setEnabled(False)

    def show_shortcuts(self) -> None:
        from .shortcuts_dialog import ShortcutsDialog

        ShortcutsDialog(self.shortcuts, self).exec()

    # ==== background similarity, focus, the place-name field's undo ============================
    def _request_similarity(self, *_args) -> None:
        """Compute the similarity matrix off the UI thread, when its tab is shown (20k nodes: seconds)."""
        if self.tabs.currentWidget() is not self.similarity_view or self.doc.similarity_ready():
            return
        job = self.doc.similarity_job()
        if job is None:
            return
        topomap = self.doc.topomap
        self.similarity_worker.submit(job, lambda sim: self.doc.set_similarity(topomap, sim),
                                      lambda exc: self.error(f"Similarity matrix failed: {exc}"))

    def _focus_changed(self, _old, new) -> None:
        """A visible frame around the frame viewer while it has the keys (defect 6)."""
        inside = new is not None and (new is self.frame_viewer or self.frame_viewer.isAncestorOf(new))
        self.frame_viewer.canvas.setStyleSheet(FOCUS_FRAME if inside else "")
        self.frame_viewer.setProperty("keyFocus", inside)

    def eventFilter(self, watched, event) -> bool:
        """Undo/redo keys in the place-name field go to the app once the name is applied (defect 7):
        the field keeps them only while it holds an edit not applied yet."""
        if watched is self.node_panel.name and event.type() == QEvent.ShortcutOverride:
            undo_keys = (QKeySequence.Undo, QKeySequence.Redo)
            if any(event.matches(k) for k in undo_keys) or event.keyCombination() == QKeyCombination(
                    Qt.ControlModifier, Qt.Key_Y):
                k = self.node_panel.node_index
                applied = (self.doc.label_of_frame(int(self.doc.node_frames()[k]))
                           if self.doc.has_map and k is not None else "")
                if self.node_panel.name.text().strip() == applied:
                    event.ignore()
                    self._name_follows_undo = True
                    return True  # not the field's: the window's Undo/Redo action runs
        return super().eventFilter(watched, event)

    def _undo_moved(self, *_args) -> None:
        """After an undo/redo typed in the place-name field, the field shows the name now applied."""
        if getattr(self, "_name_follows_undo", False):
            self._name_follows_undo = False
            k = self.node_panel.node_index
            if self.doc.has_map and k is not None:
                self.node_panel.name.setText(self.doc.label_of_frame(int(self.doc.node_frames()[k])))

    def show_about(self) -> None:
        from engine import __version__

        QMessageBox.about(self, "About panotopo",
                          f"<b>panotopo {__version__}</b><br>Topological maps from 360-degree recordings: "
                          "panorama shift, visual place recognition, curated loop closures, GraphML out.")

    def showEvent(self, event) -> None:
        super().showEvent(event)
        if not getattr(self, "_split_done", False):  # after the first layout: real widths are known
            self._split_done = True
            QTimer.singleShot(0, self._initial_split)

    def _initial_split(self) -> None:
        split_views(self)  # gui-b: gui.window_layout (issue 14, defects 3 and 4)

    # ==== drag and drop, closing ============================================================
    def dragEnterEvent(self, event: QDragEnterEvent) -> None:
        if event.mimeData().hasUrls() and any(u.isLocalFile() for u in event.mimeData().urls()):
            event.acceptProposedAction()

    def dropEvent(self, event: QDropEvent) -> None:
        paths = [u.toLocalFile() for u in event.mimeData().urls() if u.isLocalFile()]
        if paths:
            event.acceptProposedAction()
            QTimer.singleShot(0, lambda: self.open_path(paths[0]))

    def closeEvent(self, event: QCloseEvent) -> None:
        if not self.maybe_save():
            event.ignore()
            return
        self.shutdown()
        if self.interactive:
            self.settings.setValue("window/geometry", self.saveGeometry())
        event.accept()

    def shutdown(self) -> None:
        """Stop the worker threads and timers and release the recording."""
        self.autosave_timer.stop()
        self.frame_viewer.shutdown()
        self.pair_view.shutdown()
        self.graph_view.shutdown()
        self.runner.stop()
        self.remapper.stop()
        self.similarity_worker.stop()
        self.files.close()  # the records stay until a save compacts them; nothing empty is left
        self.doc.journal = None
        app = QApplication.instance()
        if app is not None and self._watching_focus:
            self._watching_focus = False
            app.focusChanged.disconnect(self._focus_changed)
        self.doc.close()


def _default_settings() -> dict:
    """resources/default_settings.json, or built-in values if it is missing or broken."""
    fallback = {"map": {}, "describe": {}, "eval": {}, "ui": {}, "shortcuts": {}}
    try:
        import resources

        data = resources.default_settings()
    except Exception:  # the window must open even with a damaged install
        data = {}
    out = {k: dict(data.get(k) or {}) for k in fallback}
    user = _user_settings()
    for section in fallback:
        if isinstance(user.get(section), dict):
            out[section].update(user[section])
    return out


def user_settings_path() -> Path:
    """The user's settings file: same sections as resources/default_settings.json, each optional."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / APP_NAME / "settings.json"


def _user_settings() -> dict:
    path = user_settings_path()
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:  # a broken file must not stop the app
        print(f"panotopo: {path}: ignored ({exc.__class__.__name__})", file=sys.stderr)
        return {}
    return data if isinstance(data, dict) else {}


def _settle_garbage_collector() -> None:
    """Collect once, then move everything alive to the collector's permanent generation.

    After a run the process holds millions of long-lived objects (torch, Qt, the engine's
    modules, the descriptors' metadata). Each full collection walked all of them: 200 ms
    with the GIL held, a stall of the window, every few re-maps of a 20k-node map
    (benchmarks/bench_ui_stall.py). Frozen, they are skipped; what is made later (the next
    maps) is collected as usual. One full collection per run is the price.
    """
    import gc

    gc.collect()
    gc.freeze()


def _app_icon() -> QIcon:
    icon = QIcon()
    try:
        import resources

        for path in resources.icon_paths():
            if path.is_file():
                icon.addFile(str(path))
    except Exception:
        pass
    return icon


def _describe_settings(data: dict, default_options: dict):
    from engine.pipeline import DescribeSettings

    known = set(DescribeSettings.__dataclass_fields__)
    values = {k: v for k, v in data.items() if k in known}
    if not values.get("options") and default_options:
        values["options"] = dict(default_options)
    try:
        return DescribeSettings(**values)
    except TypeError:
        raise InputError("the session's describe settings are malformed") from None


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    m, s = divmod(seconds, 60)
    if m < 60:
        return f"{m} min {s:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"
