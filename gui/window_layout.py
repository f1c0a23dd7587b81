"""How the main window shares the screen between its views, from 1280x720 up.

Left column: what is being looked at, the frame viewer (as tall as its two
panoramas), the graph and similarity tabs, and the node panel. Right column: the
review queue above the pair view, both as wide as the column. A long review lives
in the right column (issue 43, defect 7: with the graph above the queue, the table
showed 7-9 rows at 1500x950 and at 1920x1080): the pair view gets the height of its
two panoramas side by side plus its texts and buttons, the queue all the rest (at
1920x1080 well over 15 rows). In the left dock column the evaluation gets the height
of its few rows and the parameters (a long, scrolling list) the rest.
"""

from __future__ import annotations

from PySide6.QtCore import QRect, Qt

# Share of the central width for the left column (at least its minimum width).
LEFT_SHARE = 0.36
# Height of the frame viewer's texts and controls beyond its two panoramas (pixels).
VIEWER_EXTRA = 122
# Height the graph needs at least beside the node panel; less, and the panel becomes a tab.
GRAPH_MIN = 260
# Height kept for the node panel under the graph (pixels).
NODE_PANEL_MIN = 150
# Height of the pair view's title, evidence, caption and buttons beyond its panoramas (pixels).
PAIR_EXTRA = 120
# Most of the right column the pair view may take: the queue keeps the rest.
PAIR_MAX_SHARE = 0.5


def split_views(window) -> None:
    """Size the columns (after the first layout, when real sizes are known)."""
    total = window.main_splitter.width()
    if total <= 400:   # not laid out yet
        return
    left = max(int(LEFT_SHARE * total), window.left_splitter.minimumSizeHint().width())
    window.main_splitter.setSizes([left, total - left])
    right_width, height = total - left, window.bottom_splitter.height()
    # Two panoramas (2:1) side by side across the column, then the texts and buttons.
    pair = min(int(right_width / 4) + PAIR_EXTRA, int(PAIR_MAX_SHARE * height))
    window.bottom_splitter.setSizes([height - pair, pair])
    docks = (window.params_dock, window.eval_dock)
    if all(d.isVisible() and not d.isFloating() for d in docks):
        evaluation = window.eval_dock.sizeHint().height()
        window.resizeDocks(list(docks), [sum(d.height() for d in docks) - evaluation, evaluation], Qt.Vertical)
    column = window.left_splitter.height()
    viewer = min(left // 2 + VIEWER_EXTRA, max(column // 2, 0))
    node = max(NODE_PANEL_MIN, window.node_panel.minimumSizeHint().height())
    if column - viewer - node < GRAPH_MIN and window.node_panel.parent() is not window.tabs:
        # A short screen (1280x720): the node panel becomes a tab beside the graph, which
        # would otherwise be a strip a few pixels high.
        window.tabs.addTab(window.node_panel, "Current node")
        node = 0
    graph = column - viewer - node
    sizes = [viewer, graph, node] if window.left_splitter.count() == 3 else [viewer, graph]
    window.left_splitter.setSizes(sizes)


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
