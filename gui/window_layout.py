"""How the main window shares a narrow screen (a 1280x720 laptop) between its views.

Beside the parameter docks, a 1280-px window leaves about 950 px for the views:
too little for the frame viewer, the loop table (its Status column last) and the
pair view side by side. So the table and the pair view are stacked instead, both as
wide as the right column: the table shows every column, and the pair view, wide
and short, puts its two panoramas side by side (``PairView`` picks that itself).
"""

from __future__ import annotations

from PySide6.QtCore import Qt

# Shares of the right column's height: graph, table, pair view (the pair view is the
# evidence a decision rests on, so it gets the most).
RIGHT_SHARES = (0.36, 0.26, 0.38)
# Share of the central width for the frame viewer column (at least its minimum width).
LEFT_SHARE = 0.30


def split_for_narrow_window(window) -> None:
    """Stack the loop table above the pair view and size the columns for a narrow window."""
    total = window.main_splitter.width()
    left = max(int(LEFT_SHARE * total), window.left_splitter.minimumSizeHint().width())
    window.main_splitter.setSizes([left, total - left])
    window.bottom_splitter.setOrientation(Qt.Vertical)
    right = window.main_splitter.widget(1)
    height = right.height()
    graph, table, _ = (int(share * height) for share in RIGHT_SHARES)
    right.setSizes([graph, height - graph])
    window.bottom_splitter.setSizes([table, height - graph - table])
    viewer_height = window.left_splitter.height()
    viewer = min(left + 122, viewer_height - 160)   # the two panoramas at this width, the node panel below
    window.left_splitter.setSizes([viewer, viewer_height - viewer])
