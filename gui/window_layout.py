"""How the main window shares the screen between its views, from 1280x720 up.

Beside the parameter docks, a 1280-px window leaves about 950 px for the views: too
little for the frame viewer, the loop table (its Status column last) and the pair view
side by side (issue 14, defects 3 and 4); on a 1920-px screen the pair view beside the
table got ~450 px, its panoramas ~340 px wide. So the table and the pair view are
stacked in the right column, both as wide as it: the table shows every column, and
the pair view, wide and short, puts its two panoramas side by side (``PairView``
picks that itself), each about half the column wide. In the left dock column the
evaluation gets the height of its few rows and the parameters (a long, scrolling
list with ``verified``'s thresholds) the rest.
"""

from __future__ import annotations

from PySide6.QtCore import QRect, Qt

# Shares of the right column's height: graph, table, pair view (the pair view shows the
# evidence a decision rests on, so it gets the most).
RIGHT_SHARES = (0.36, 0.26, 0.38)
# Share of the central width for the frame viewer column (at least its minimum width).
LEFT_SHARE = 0.30
# Height of the frame viewer's texts and controls beyond its two panoramas (pixels).
VIEWER_EXTRA = 122
# Height kept for the node panel under the frame viewer (pixels).
NODE_PANEL_MIN = 160


def split_views(window) -> None:
    """Size the columns and stack the loop table above the pair view (after the first layout)."""
    total = window.main_splitter.width()
    if total <= 400:   # not laid out yet
        return
    left = max(int(LEFT_SHARE * total), window.left_splitter.minimumSizeHint().width())
    window.main_splitter.setSizes([left, total - left])
    window.bottom_splitter.setOrientation(Qt.Vertical)
    right = window.main_splitter.widget(1)
    height = right.height()
    graph, table, _ = (int(share * height) for share in RIGHT_SHARES)
    right.setSizes([graph, height - graph])
    window.bottom_splitter.setSizes([table, height - graph - table])
    docks = (window.params_dock, window.eval_dock)
    if all(d.isVisible() and not d.isFloating() for d in docks):
        evaluation = window.eval_dock.sizeHint().height()
        window.resizeDocks(list(docks), [sum(d.height() for d in docks) - evaluation, evaluation], Qt.Vertical)
    column = window.left_splitter.height()
    if column > NODE_PANEL_MIN + 140:   # the viewer as tall as its two panoramas, the node panel below
        viewer = min(left + VIEWER_EXTRA, column - NODE_PANEL_MIN)
        window.left_splitter.setSizes([viewer, column - viewer])


# Room a window manager takes around a window: its frame, its title bar (pixels).
FRAME_ALLOWANCE = (16, 48)


def fit_to_screen(window) -> None:
    """Make ``window`` fit its screen's available geometry (issue 43, defect 1).

    The first size (1500x950 by default) and a size restored from a bigger screen are
    clamped to the room the screen leaves (panels and docks excluded), frame included,
    and the window is moved inside it: on a 1280x720 screen the evaluation panel, the
    pair view, the decision buttons and the status bar are all on screen.
    """
    from PySide6.QtGui import QGuiApplication

    screen = window.screen() or QGuiApplication.primaryScreen()
    if screen is None:
        return
    room: QRect = screen.availableGeometry()
    if window.isMaximized() or window.isFullScreen():
        return
    width = min(window.width(), room.width() - FRAME_ALLOWANCE[0])
    height = min(window.height(), room.height() - FRAME_ALLOWANCE[1])
    if (width, height) != (window.width(), window.height()):
        window.resize(max(width, 320), max(height, 240))
    x = min(max(window.x(), room.x()), room.right() - window.width() - FRAME_ALLOWANCE[0] + 1)
    y = min(max(window.y(), room.y()), room.bottom() - window.height() - FRAME_ALLOWANCE[1] + 1)
    if (x, y) != (window.x(), window.y()):
        window.move(max(x, room.x()), max(y, room.y()))
