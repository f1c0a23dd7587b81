"""The application model: everything the desktop app knows and decides, without Qt.

The Qt window (``gui.main_window`` and its views) is a thin layer over this package:
it shows the model and turns clicks and keys into model calls. Nothing here imports
Qt (import-linter contract "gui.model never imports Qt" in pyproject.toml, checked by
tests/test_layers.py), so the model is tested in plain Python (tests/test_app_model.py).

* ``document``: the open map (``MapDocument``): descriptors, map, poses, decisions.
* ``history``: undo/redo of plain command objects (``History``, ``Command``).
* ``commands``: the decisions as commands (status, manual loops, labels).
* ``queue``: the review queue (``ReviewQueue``): ranking, filters, counts, bulk actions.
* ``keys``: the one table of keyboard shortcuts.
* ``journal``: decision records (what the write-through journal stores), checked, and their replay.
* ``recording_files``: the session, autosave and journal beside a recording: which saved
  session belongs to a file, unsaved work restored or dropped, files written only as ours.
* ``run_plan``: what a parameter change asks for (describe again, re-map, refuse, wait) and
  which thresholds are known before the map is built.
* ``layout``: the drawing of the map as decided (no ground truth), from a copy of it.
* ``similarity``: the node similarity matrix with a picture-sized preview.
* ``loop_key``: loops addressed by the source frames of their two nodes.
* ``site``: several recordings open as one site: what to map, the site file, each
  recording's stretch of one site timeline and its frames read from its own recording.
"""

from .commands import AddManualLoop, RemoveLoop, SetLabel, SetStatuses
from .document import LoopKey, LoopRow, MapDocument
from .history import Command, History
from .queue import ReviewQueue

__all__ = ["AddManualLoop", "Command", "History", "LoopKey", "LoopRow", "MapDocument", "RemoveLoop",
           "ReviewQueue", "SetLabel", "SetStatuses"]
