"""Colours, pens and the pyqtgraph settings shared by every view."""

from __future__ import annotations

import pyqtgraph as pg
from PySide6.QtCore import Qt

# Images are numpy (row, column, channel); no OpenGL (works on any machine, offscreen too).
pg.setConfigOptions(imageAxisOrder="row-major", useOpenGL=False, antialias=True)

# One colour per loop status, used by the graph, the matrix, the table and the legend.
STATUS_COLORS = {
    "candidate": "#b03a8c",  # plum: found, not accepted automatically, waits for a person
    "auto": "#f39c12",       # orange: accepted by the engine, a person may still decide
    "confirmed": "#27ae60",  # green
    "rejected": "#c0392b",   # red, drawn faint and dashed
    "manual": "#2e86de",     # blue
}
STATUS_LABELS = {
    "candidate": "candidate",
    "auto": "auto",
    "confirmed": "confirmed",
    "rejected": "rejected",
    "manual": "manual",
}
# The order in which the views list the statuses (toggles, legends).
STATUS_ORDER = ("candidate", "auto", "confirmed", "manual", "rejected")
SEQUENTIAL_COLOR = "#7f8c8d"
# One colour per recording of a site (path, nodes, the table's node cells, the legend): dark and
# unlike the loop statuses' colours, so that a path is never read as a loop.
RECORDING_COLORS = ("#00838f", "#6d4c41", "#5e35b1", "#7cb342", "#546e7a", "#d81b60", "#1565c0", "#9e7c00")


def recording_color(i: int) -> str:
    """The colour of a site's ``i``-th recording (the palette repeats past eight)."""
    return RECORDING_COLORS[int(i) % len(RECORDING_COLORS)]
NODE_COLOR = "#34495e"
CURRENT_COLOR = "#e84393"
SELECTED_COLOR = "#8e44ad"
CANONICAL_COLOR = "#e84393"
# Matched features in the pair view, as RTAB-Map draws them: inliers green, outliers red.
INLIER_COLOR = "#00e640"
OUTLIER_COLOR = "#ff3030"


def status_pen(status: str, width: float = 2.0, selected: bool = False):
    color = pg.mkColor(STATUS_COLORS.get(status, "#000"))
    if status == "rejected":
        color.setAlpha(150)
        return pg.mkPen(color, width=width, style=Qt.DashLine)
    if status == "candidate":
        return pg.mkPen(color, width=width * (2 if selected else 1), style=Qt.DashDotLine)
    return pg.mkPen(color, width=width * (2 if selected else 1))


def panorama_view() -> pg.ViewBox:
    """A ViewBox that shows an image with row 0 on top and square pixels."""
    view = pg.ViewBox(lockAspect=True, invertY=True, enableMenu=False)
    view.setDefaultPadding(0.0)
    return view
