"""Small hand-made maps for the view tests: a Document without running the engine."""

from __future__ import annotations

import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.graph import TopoMap
from engine.loops import LoopCandidate
from engine.params import MapParams
from engine.poses import Poses


def make_doc(positions=None, loops=(), n: int = 20, seed: int = 0):
    """A Document with ``n`` nodes (one per frame, 1 s apart), ``loops`` = [(a, b, status), ...].

    ``positions`` (n, 2) become ground-truth poses; None leaves the map unlocalised.
    """
    from gui.document import Document

    rng = np.random.default_rng(seed)
    vectors = rng.normal(size=(n, 16)).astype(np.float32)
    vectors /= np.linalg.norm(vectors, axis=1, keepdims=True)
    descs = Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                        shifts=np.zeros(n, dtype=np.int64), vectors=vectors)
    cands = [LoopCandidate(a=a, b=b, similarity=0.9, window_count=1) for a, b, _ in loops]
    topomap = TopoMap.build(descs, np.arange(n), cands, MapParams())
    for a, b, status in loops:
        topomap.graph.edges[f"n{a}", f"n{b}"]["status"] = status
    doc = Document()
    if positions is not None:
        p = np.asarray(positions, dtype=np.float64)
        doc.poses = Poses(t=np.arange(n, dtype=np.float64), x=p[:, 0], y=p[:, 1])
    doc.replace_map(topomap, descs)
    return doc


def square_walk(n: int = 20, side: float = 5.0) -> np.ndarray:
    """(n, 2) positions round a square, the last node back at the first one's place."""
    t = np.linspace(0.0, 4.0, n)
    corners = np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], dtype=np.float64)
    i = np.minimum(t.astype(int), 3)
    f = (t - i)[:, None]
    return corners[i] * (1 - f) + corners[i + 1] * f


def colour_pixels(widget, colour: str, tol: int = 40, centre=None, radius: int = 10_000) -> int:
    """How many pixels of ``widget`` (rendered) are within ``tol`` of ``colour``, near ``centre``."""
    from PySide6.QtGui import QColor

    pixmap = widget.grab()
    img = pixmap.toImage()
    img = img.convertToFormat(img.Format.Format_RGB888)
    w, h = img.width(), img.height()
    arr = np.frombuffer(img.constBits(), dtype=np.uint8, count=img.bytesPerLine() * h)
    arr = arr.reshape(h, img.bytesPerLine())[:, : 3 * w].reshape(h, w, 3).astype(int)
    c = QColor(colour)
    near = np.abs(arr - np.array([c.red(), c.green(), c.blue()])).max(axis=2) <= tol
    if centre is not None:
        ratio = pixmap.devicePixelRatio()
        yy, xx = np.mgrid[0:h, 0:w]
        near &= np.hypot(xx - centre[0] * ratio, yy - centre[1] * ratio) <= radius * ratio
    return int(near.sum())


def pano_folder(path, n: int = 20, revisit=(0, 15), roll: int = 64, width: int = 256):
    """A folder of ``n`` real panoramas (crops of the example panorama's columns at other
    headings); frame ``revisit[1]`` is frame ``revisit[0]`` turned by ``roll`` columns."""
    from pathlib import Path

    from PIL import Image

    base = Image.open(Path(__file__).parent / "data" / "examplepano_1024.jpg").convert("RGB")
    base = np.asarray(base.resize((width, width // 2)))
    out = Path(path)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    frames = []
    for k in range(n):
        img = np.roll(base, int(rng.integers(0, width)), axis=1)
        img = np.flipud(img) if k % 2 else img  # other places look different
        frames.append(img)
    frames[revisit[1]] = np.roll(frames[revisit[0]], roll, axis=1)
    for k, img in enumerate(frames):
        Image.fromarray(np.ascontiguousarray(img)).save(out / f"frame_{k:04d}.png")
    return out, frames


@pytest.fixture
def boxes(monkeypatch):
    """Every message box the app shows, as (kind, text), answered at once (questions: No)."""
    from PySide6.QtWidgets import QMessageBox

    shown: list = []
    for kind in ("critical", "warning", "information"):
        monkeypatch.setattr(QMessageBox, kind, lambda *a, k=kind, **kw: shown.append((k, a[2])) or QMessageBox.Ok)
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **kw: shown.append(("question", a[2])) or QMessageBox.No)
    return shown


def window_maker(qtbot, tmp_path, method=None, size=None):
    """For a ``make_window`` fixture (``yield from``): ``make(size=...)`` builds a shown
    MainWindow with settings and cache under ``tmp_path`` (``method`` chosen in its panel,
    resized to ``size`` when given); every window made is shut down afterwards, its changes
    marked saved so that no question is asked."""
    from PySide6.QtCore import QSettings

    from gui.main_window import MainWindow

    windows = []

    def make(size=size):
        w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), cache_root=str(tmp_path))
        qtbot.addWidget(w)
        if method is not None:
            w.params_panel.method.setCurrentIndex(w.params_panel.method.findData(method))
        if size is not None:
            w.resize(*size)
        w.show()
        windows.append(w)
        return w

    yield make
    for w in windows:
        w.undo_stack.setClean()
        w._extra_dirty = False
        w.shutdown()
