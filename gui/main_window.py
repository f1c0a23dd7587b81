"""The main window: a thin Qt layer that builds the views and wires them to controllers.

Every concern lives elsewhere, each in one place: the document and every decision in
the Qt-free ``gui.model`` (``document``, ``queue``, ``recording_files``, ``run_plan``,
``layout``); opening files in ``gui.opening``; runs and re-maps in
``gui.run_control``; curation and the shared selection in ``gui.curation``; saving
and exporting in ``gui.session_control``; actions and menus in
``gui.window_actions``; how the screen is shared in ``gui.window_layout``; all
background work on ``gui.background.Worker``. The window keeps the views, the status
bar, the messages, the title, recent files, focus and closing.

Layout: left the frame viewer, the graph and similarity tabs and the node panel;
right the review queue above the pair view; docks for the parameters and the
evaluation.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

from PySide6.QtCore import QEvent, QKeyCombination, QSettings, Qt, QTimer, Signal
from PySide6.QtGui import QCloseEvent, QDragEnterEvent, QDropEvent, QKeySequence, QUndoStack
from PySide6.QtWidgets import (QApplication, QDockWidget, QLabel, QMainWindow, QMessageBox, QProgressBar,
                               QPushButton, QSplitter, QTabWidget)

from . import window_actions
from .app_settings import APP_NAME, app_icon, default_settings
from .background import Worker
from .commands import QtHistory
from .curation import Curation
from .document import Document
from .eval_panel import EvalPanel
from .frame_cache import FrameCache
from .frame_viewer import FrameViewer
from .graph_view import GraphView
from .loop_table import LoopTable
from .model.keys import bad_overrides, shortcut_table
from .model.layout import path_layout
from .model.queue import ReviewQueue
from .model.recording_files import RecordingFiles
from .node_panel import NodePanel
from .opening import Opening
from .pair_view import PairView
from .params_panel import ParamsPanel
from .run_control import RunControl
from .session_control import SessionControl
from .similarity_view import SimilarityView
from .window_layout import fit_to_screen, split_views
from .worker import RunController

FOCUS_FRAME = "border: 2px solid #3daee9;"  # the frame viewer has the keyboard


class MainWindow(QMainWindow):
    mapReady = Signal()          # a run (or a parameter change) produced the map now shown
    runFailed = Signal(str)
    runCancelled = Signal()

    def __init__(self, settings: Optional[QSettings] = None, cache_root: Optional[str] = None,
                 describe_options: Optional[dict] = None, interactive: bool = True) -> None:
        super().__init__()
        self.settings = settings if settings is not None else QSettings(APP_NAME, APP_NAME)
        self.defaults = default_settings()
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
        self._pending_decisions: Optional[dict] = None   # of a session being opened, until its map is there
        self._extra_dirty = False     # changes outside the undo stack (poses loaded)
        self._last_error = ""
        # The controllers, one concern each (see the module docstring).
        self.opening = Opening(self)
        self.runs = RunControl(self)
        self.curation = Curation(self)
        self.sessions = SessionControl(self)

        self._build_views()
        window_actions.build_actions(self)
        window_actions.build_menus(self)
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
            for worker in self.workers():
                app.aboutToQuit.connect(worker.stop)
        self.autosave_timer = QTimer(self)
        self.autosave_timer.setInterval(int(1000 * self.defaults["ui"].get("autosave_seconds", 30)))
        self.autosave_timer.timeout.connect(self.sessions.autosave)
        self.autosave_timer.start()
        self.setAcceptDrops(True)
        self.setWindowIcon(app_icon())
        ui = self.defaults["ui"]
        self.resize(int(ui.get("window_width", 1500)), int(ui.get("window_height", 950)))
        geometry = self.settings.value("window/geometry")
        if geometry is not None and interactive:
            self.restoreGeometry(geometry)
        fit_to_screen(self)   # the default size, or one saved on a bigger screen, fits this one

    # ==== the window's commands: what its menus, scripts and tests call ====================
    def open_path(self, path: str, topic: Optional[str] = None, pose_topic: Optional[str] = None,
                  run: bool = True) -> bool:
        return self.opening.open_path(path, topic, pose_topic, run=run)

    def open_paths(self, paths: list, run: bool = True) -> bool:
        return self.opening.open_paths(paths, run=run)

    def load_poses(self, path: str, topic: Optional[str] = None) -> bool:
        return self.opening.load_poses(path, topic)

    def start_run(self) -> None:
        self.runs.start_run()

    def cancel_run(self) -> None:
        self.runs.cancel_run()

    def decide(self, status: str) -> None:
        self.curation.decide(status)

    def add_manual_loop(self, key) -> bool:
        return self.curation.add_manual_loop(key)

    def remove_manual_loop(self, key) -> None:
        self.curation.remove_manual_loop(key)

    def set_label(self, frame: int, label: str) -> None:
        self.curation.set_label(frame, label)

    def select_loop(self, key) -> None:
        self.curation.select_loop(key)

    def select_first_loop(self) -> bool:
        return self.curation.select_first_loop()

    def is_modified(self) -> bool:
        return self.sessions.is_modified()

    def current_session(self):
        return self.sessions.current_session()

    def save_session(self, path: Optional[str] = None) -> bool:
        return self.sessions.save_session(path)

    def autosave(self) -> None:
        self.sessions.autosave()

    def maybe_save(self) -> bool:
        return self.sessions.maybe_save()

    def export_graphml(self, path: str) -> bool:
        return self.sessions.export_graphml(path)

    def export_graph_png(self, path: str) -> bool:
        return self.sessions.export_graph_png(path)

    # ==== construction ==============================================================
    def _build_views(self) -> None:
        self.frame_viewer = FrameViewer(self.doc, self.frames)
        self.graph_view = GraphView(self.doc)
        self.similarity_view = SimilarityView(self.doc)
        self.loop_table = LoopTable(self.doc)
        self.pair_view = PairView(self.doc, self.frames)
        self.node_panel = NodePanel(self.doc)
        self.params_panel = ParamsPanel()
        self.runs._apply_default_settings()
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
        self.cancel_button.clicked.connect(self.runs.cancel_run)
        # Shown for as long as decisions are not journaled (issue 43, defect 14): not only a log line.
        self.journal_label = QLabel()
        self.journal_label.setStyleSheet("color: #c0392b; font-weight: bold")
        self.journal_label.setVisible(False)
        status.addPermanentWidget(self.journal_label)
        status.addPermanentWidget(self.summary_label)
        status.addPermanentWidget(self.progress_bar)
        status.addPermanentWidget(self.eta_label)
        status.addPermanentWidget(self.cancel_button)
        self.runs._show_progress(False)
        status.showMessage("Open a recording to start (File ▸ Open, or drop a file here)")

    def _connect(self) -> None:
        # Bound methods, not lambdas: Qt drops these connections when the window dies.
        self.undo_stack.cleanChanged.connect(self._update_title)
        self.undo_stack.indexChanged.connect(self._update_actions)
        self.undo_stack.indexChanged.connect(self._undo_moved)
        self.runner.progress.connect(self.runs._on_progress)
        self.runner.finished.connect(self.runs._on_run_finished)
        self.runner.failed.connect(self.runs._on_run_failed)
        self.runner.cancelled.connect(self.runs._on_run_cancelled)

        self.frame_viewer.frameChanged.connect(self.curation._frame_changed)
        self.graph_view.nodeClicked.connect(self.curation.show_node)
        self.graph_view.loopClicked.connect(self.curation.select_loop)
        self.graph_view.manualLoopRequested.connect(self.curation._ctrl_click_loop)
        self.similarity_view.pairClicked.connect(self.curation.select_pair)
        self.node_panel.labelEdited.connect(self.curation.set_label)
        self.node_panel.loopActivated.connect(self.curation.select_loop)
        self.node_panel.addLoopRequested.connect(lambda k: self.curation.manual_loop_dialog(k))
        self.loop_table.loopSelected.connect(self.curation._loop_selected)
        self.pair_view.decide.connect(self.curation.decide_pair)
        self.pair_view.addManual.connect(self.curation.add_manual_loop)
        self.pair_view.removeManual.connect(self.curation.remove_manual_loop)
        self.params_panel.paramsEdited.connect(self.runs._params_edited)
        self.params_panel.calibrateRequested.connect(self.runs.calibrate_thresholds)
        self.params_panel.runRequested.connect(self.runs.start_run)
        self.params_panel.describeEdited.connect(
            lambda: self.statusBar().showMessage("Descriptor settings changed: press Run (F5) to describe again", 8000))
        self.doc.mapReplaced.connect(self.curation._sync_current_node)
        self.doc.mapReplaced.connect(self._update_summary)
        self.doc.loopsChanged.connect(self._update_summary)
        self.doc.mapReplaced.connect(self._update_actions)
        self.doc.loopsChanged.connect(self._update_actions)
        self.doc.mapReplaced.connect(self.runs._request_similarity)
        self.doc.journalFailed.connect(self.opening._journal_failed)
        self.tabs.currentChanged.connect(self.runs._request_similarity)
        # Ctrl+Z in the place-name field: the app's undo once the name is applied (defect 7).
        self.node_panel.name.installEventFilter(self)
        app = QApplication.instance()
        self._watching_focus = app is not None
        if app is not None:
            app.focusChanged.connect(self._focus_changed)

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
        self.setWindowModified(self.sessions.is_modified())

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
        window_actions.rebuild_recent_menu(self)

    def show_shortcuts(self) -> None:
        from .shortcuts_dialog import ShortcutsDialog

        ShortcutsDialog(self.shortcuts, self).exec()

    # ==== background similarity, focus, the place-name field's undo ============================

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
            QTimer.singleShot(0, lambda: self.opening.open_paths(paths))   # several: one site

    def closeEvent(self, event: QCloseEvent) -> None:
        if not self.sessions.maybe_save():
            event.ignore()
            return
        self.shutdown()
        if self.interactive:
            self.settings.setValue("window/geometry", self.saveGeometry())
        event.accept()

    def workers(self) -> list:
        """Every background worker of the window and its views (``gui.background.Worker``; the
        run's through its controller, which forgets the run when it stops)."""
        return [self.runner, self.remapper, self.similarity_worker, self.graph_view.layout_worker,
                self.pair_view.match_worker, self.frame_viewer.loader.worker]

    def shutdown(self) -> None:
        """Stop the worker threads and timers and release the recording."""
        self.autosave_timer.stop()
        self.frame_viewer.shutdown()
        self.pair_view.shutdown()
        for worker in self.workers():   # quit + wait, each, before the window goes
            worker.stop()
        self.files.close()  # the records stay until a save compacts them; nothing empty is left
        self.doc.journal = None
        app = QApplication.instance()
        if app is not None and self._watching_focus:
            self._watching_focus = False
            app.focusChanged.disconnect(self._focus_changed)
        self.doc.close()

