"""The main window's actions and menus, built from the one table of keys (``gui.model.keys``).

Each action calls the controller that owns its concern (``window.opening``,
``window.runs``, ``window.curation``, ``window.sessions``); ``set_keys`` gives an
action the keys of its entry in the shortcut table (settings overrides applied).
"""

from __future__ import annotations

from functools import partial
from typing import Optional

from PySide6.QtGui import QAction, QKeySequence


def action(w, text: str, slot, key: Optional[str] = None, tip: str = "") -> QAction:
    """A menu action; ``key`` names its entry in the shortcut table (gui.model.keys)."""
    action = QAction(text, w)
    if key is not None:
        set_keys(w, action, key)
    if tip:
        action.setStatusTip(tip)
        action.setToolTip(tip)
    action.triggered.connect(lambda checked=False: slot())
    w.addAction(action)  # shortcuts work even with the menu bar hidden
    return action


def set_keys(w, action: QAction, key: str) -> None:
    keys = next(s.keys for s in w.shortcuts if s.action == key)
    action.setShortcuts([QKeySequence(k) for k in keys])
    w.action_of_key[key] = action


def build_actions(w) -> None:
    A = partial(action, w)
    w.action_of_key: dict[str, QAction] = {}
    w.open_action = A("&Open…", w.opening.open_dialog, "open",
                         "Open a video, a ROS bag, a folder of images, a session or a descriptors .npz")
    w.open_folder_action = A("Open &folder or ROS2 bag…", w.opening.open_folder_dialog, None,
                                "Open a folder of panoramas or a ROS2 bag directory")
    w.poses_action = A("Load &poses…", w.opening.load_poses_dialog, None,
                          "Load ground-truth poses (CSV t,x,y[,yaw] or a bag topic) for evaluation")
    w.save_action = A("&Save session", w.sessions.save_session, "save",
                         "Save decisions and parameters next to the recording")
    w.save_as_action = A("Save session &as…", w.sessions.save_session_as, "save_as")
    w.export_action = A("&Export corrected graph (GraphML)…", w.sessions.export_graphml_dialog, "export",
                           "Write the corrected map: rejected loops left out, confirmed and manual kept")
    w.export_png_action = A("Export graph &picture (PNG)…", w.sessions.export_png_dialog, None,
                               "Save a picture of the graph view")
    w.export_plot_action = A("Export evaluation &plot (PNG)…", w.sessions.export_plot_dialog, None,
                                "Map and similarity matrix with ground-truth colours")
    w.quit_action = A("&Quit", w.close, "quit")

    w.undo_action = w.undo_stack.createUndoAction(w, "&Undo")
    set_keys(w, w.undo_action, "undo")
    w.redo_action = w.undo_stack.createRedoAction(w, "&Redo")
    set_keys(w, w.redo_action, "redo")
    w.addAction(w.undo_action)
    w.addAction(w.redo_action)
    w.label_action = A("Name this &place…", w.curation.name_place_dialog, "name_place",
                          "Give the current node a place name")

    w.confirm_action = A("&Confirm selected loops", lambda: w.curation.decide("confirmed"), "confirm",
                            "Same place: keep the selected loops")
    w.reject_action = A("&Reject selected loops", lambda: w.curation.decide("rejected"), "reject",
                           "Different places: drop the selected loops")
    w.reset_action = A("Rese&t selected loops", lambda: w.curation.decide("auto"), "reset",
                          "Back to undecided")
    w.next_undecided_action = A("Next &undecided loop", w.curation.next_undecided, "next_undecided",
                                   "Select the next loop nobody has decided on yet")
    w.next_action = A("&Next loop", lambda: w.loop_table.step(1), "next")
    w.prev_action = A("&Previous loop", lambda: w.loop_table.step(-1), "previous")
    w.focus_queue_action = A("&Go to the review queue", w.curation.focus_queue, "focus_queue",
                                "Move the keyboard to the review queue (about 40 Tabs from the parameters)")
    w.reject_below_action = A("Reject all &below this one", w.curation.reject_below, "reject_below",
                                 "Reject every undecided loop whose evidence is below the selected loop's")
    w.manual_action = A("&Add manual loop…", w.curation.manual_loop_dialog, "manual_loop",
                           "Join two nodes that are the same place")
    w.remove_action = A("Re&move manual loop", w.curation.remove_selected_manual, "remove_manual")
    w.advance_action = QAction("Advance after a decision", w, checkable=True,
                                  checked=w.advance_after_decision)
    w.advance_action.toggled.connect(lambda on: setattr(w, "advance_after_decision", on))

    w.run_action = A("&Run", w.runs.start_run, "run", "Describe the recording and build the map")
    w.cancel_action = A("&Cancel run", w.runs.cancel_run, "cancel_run", "Stop the run; the current map is kept")
    w.shortcuts_action = A("&Keyboard shortcuts", w.show_shortcuts, "shortcuts")
    w.about_action = A("&About panotopo", w.show_about)


def build_menus(w) -> None:
    bar = w.menuBar()
    m = bar.addMenu("&File")
    for a in (w.open_action, w.open_folder_action):
        m.addAction(a)
    w.recent_menu = m.addMenu("Open &recent")
    m.addSeparator()
    m.addAction(w.poses_action)
    m.addSeparator()
    for a in (w.save_action, w.save_as_action):
        m.addAction(a)
    m.addSeparator()
    for a in (w.export_action, w.export_png_action, w.export_plot_action):
        m.addAction(a)
    m.addSeparator()
    m.addAction(w.quit_action)
    m = bar.addMenu("&Edit")
    for a in (w.undo_action, w.redo_action):
        m.addAction(a)
    m.addSeparator()
    m.addAction(w.label_action)
    m = bar.addMenu("&Loops")
    for a in (w.confirm_action, w.reject_action, w.reset_action):
        m.addAction(a)
    m.addSeparator()
    for a in (w.next_undecided_action, w.next_action, w.prev_action, w.focus_queue_action):
        m.addAction(a)
    m.addSeparator()
    m.addAction(w.reject_below_action)
    m.addSeparator()
    for a in (w.manual_action, w.remove_action):
        m.addAction(a)
    m.addSeparator()
    m.addAction(w.advance_action)
    m = bar.addMenu("&Run")
    m.addAction(w.run_action)
    m.addAction(w.cancel_action)
    m = bar.addMenu("&View")
    m.addAction(w.params_dock.toggleViewAction())
    m.addAction(w.eval_dock.toggleViewAction())
    m = bar.addMenu("&Help")
    m.addAction(w.shortcuts_action)
    m.addAction(w.about_action)
    rebuild_recent_menu(w)


def rebuild_recent_menu(w) -> None:
    w.recent_menu.clear()
    recent = w.recent_files()
    for path in recent:
        action = w.recent_menu.addAction(path)
        action.triggered.connect(lambda checked=False, p=path: w.opening.open_path(p))
    if not recent:
        w.recent_menu.addAction("(none)").setEnabled(False)
