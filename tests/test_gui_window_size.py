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
