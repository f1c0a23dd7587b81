"""The window fits a 1280x720 laptop screen, also on HiDPI, and panels keep their widths."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QSettings  # noqa: E402
from PySide6.QtWidgets import QSplitter, QWidget  # noqa: E402

from gui.document import Document  # noqa: E402
from gui.frame_cache import FrameCache  # noqa: E402
from gui.frame_viewer import FrameViewer  # noqa: E402

# A 1280x720 screen less a window frame (about 10 px a side) and a title bar and panel (about 50 px).
MAX_WIDTH, MAX_HEIGHT = 1260, 690

_MIN_SIZE_SCRIPT = """
import json, sys
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QApplication
app = QApplication(["panotopo"])
from gui.main_window import MainWindow
w = MainWindow(settings=QSettings(sys.argv[1], QSettings.IniFormat), interactive=False)
w.show(); app.processEvents()
# A map on screen, with the long texts a session has: a place name, a node header, a pair.
from tests.gui_maps import make_doc
doc = make_doc(None, [(0, 19, "auto")], n=1500)
w.doc.replace_map(doc.topomap, doc.descs)
w.doc.topomap.set_label("n1234", "the long corridor behind the second kitchen")
w.node_panel.show_node(1234)
w.pair_view.show_pair((0, 19))
w.frame_viewer.info.setText("<b>frame 12345</b> / 99999 &nbsp; · &nbsp; t = 1234.56 s &nbsp; · &nbsp; node "
                            "<b>n1234</b> (since frame 12340) &nbsp; · &nbsp; “the long corridor behind the second kitchen”")
app.processEvents()
hint = w.minimumSizeHint()
print(json.dumps({"w": hint.width(), "h": hint.height(), "dpr": w.devicePixelRatio()}))
w.close()
"""


def test_a_long_frame_header_does_not_widen_the_viewer(qtbot):
    doc = Document()
    viewer = FrameViewer(doc, FrameCache())
    splitter = QSplitter()
    splitter.addWidget(viewer)
    splitter.addWidget(QWidget())
    qtbot.addWidget(splitter)
    splitter.resize(900, 500)
    splitter.setSizes([300, 600])
    splitter.show()
    qtbot.waitExposed(splitter)
    before = splitter.sizes()
    viewer.info.setText("<b>frame 1234</b> / 99999 &nbsp; · &nbsp; t = 1234.56 s &nbsp; · &nbsp; node <b>n1500</b>"
                        " (since frame 1230) &nbsp; · &nbsp; “the long corridor behind the second kitchen”")
    qtbot.wait(20)
    assert viewer.minimumSizeHint().width() < 300
    assert splitter.sizes() == before, "the panel beside the viewer keeps its width"


@pytest.mark.parametrize("scale", ["1", "2"])
def test_main_window_fits_a_1280x720_screen(tmp_path, scale):
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", QT_SCALE_FACTOR=scale,
               PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", _MIN_SIZE_SCRIPT, str(tmp_path / "s.ini")], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    size = json.loads(out.stdout.strip().splitlines()[-1])
    assert size["dpr"] == float(scale), "Qt scales the window on a HiDPI screen"
    # Sizes are in device-independent pixels: a 2560x1440 screen at scale 2 is 1280x720 of them.
    assert size["w"] <= MAX_WIDTH and size["h"] <= MAX_HEIGHT, size


def test_at_1280x720_the_table_shows_its_status_column(qtbot, tmp_path):
    from gui.main_window import MainWindow

    w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), interactive=False)
    qtbot.addWidget(w)
    w.resize(1280, 720)
    w.show()
    qtbot.waitExposed(w)
    qtbot.wait(50)   # the first split happens after the first layout
    table = w.loop_table.view
    header = table.horizontalHeader()
    status = header.count() - 1
    right = header.sectionViewportPosition(status) + min(header.sectionSize(status), 40)
    assert right <= table.viewport().width(), "the Status column starts inside the visible table"
    assert w.pair_view.width() >= 380, "the pair view is wide enough to judge a pair"
    w.close()


_FIRST_SIZE_SCRIPT = """
import json, sys
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QApplication
app = QApplication(["panotopo"])
from gui.main_window import MainWindow
w = MainWindow(settings=QSettings(sys.argv[1], QSettings.IniFormat))
if len(sys.argv) > 2:
    w.resize(int(sys.argv[2]), int(sys.argv[3]))
w.show(); app.processEvents()
room = w.screen().availableGeometry()
frame = w.frameGeometry()
print(json.dumps({"w": w.width(), "h": w.height(), "x": w.x(), "y": w.y(),
                  "room": [room.x(), room.y(), room.width(), room.height()]}))
w.close()   # saves the geometry, as a quit does
w.settings.sync()
print(json.dumps({"saved": w.settings.value("window/geometry") is not None}))
"""


def _first_size(tmp_path, screen, *size):
    config = tmp_path / f"screen{screen[0]}.json"
    config.write_text(json.dumps({"screens": [{"name": "s", "x": 0, "y": 0, "width": screen[0],
                                               "height": screen[1], "logicalDpi": 96, "dpr": 1}]}))
    env = dict(os.environ, QT_QPA_PLATFORM=f"offscreen:configfile={config}",
               XDG_CONFIG_HOME=str(tmp_path / "config"),
               PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", _FIRST_SIZE_SCRIPT, str(tmp_path / "s.ini"), *map(str, size)],
                         env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert json.loads(lines[-1])["saved"]
    return json.loads(lines[-2])


def test_the_first_size_fits_a_1280x720_screen_and_a_saved_bigger_one_is_clamped(tmp_path):
    """Issue 43, defect 1: on a 1280x720 screen the window opened at 1500x950, the evaluation
    panel, the pair view, the decision buttons and the status bar off screen."""
    first = _first_size(tmp_path, (1280, 720))
    assert first["x"] + first["w"] <= 1280 and first["y"] + first["h"] <= 720, first
    big = _first_size(tmp_path, (2560, 1440), 2400, 1350)   # saved on a big screen ...
    assert big["w"] > 1500
    again = _first_size(tmp_path, (1280, 720))               # ... reopened on a small one
    assert again["x"] + again["w"] <= 1280 and again["y"] + again["h"] <= 720, again


def test_at_1280x720_the_graph_is_not_a_strip(qtbot, tmp_path):
    """With the queue and the pair view in the right column, the left column holds the frame
    viewer, the graph and the node panel: on a short screen the node panel becomes a tab."""
    from gui.main_window import MainWindow

    w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), interactive=False)
    qtbot.addWidget(w)
    w.resize(1280, 720)
    w.show()
    qtbot.waitExposed(w)
    qtbot.waitUntil(lambda: getattr(w, "_split_done", False), timeout=2000)
    qtbot.wait(50)
    assert w.graph_view.height() >= 200 and w.graph_view.width() >= 280
    w.close()
