"""Pictures of every view for the docs, from a real run on a synthetic recording.

``python -m gui.screenshots docs/screenshots [WIDTHxHEIGHT]`` renders the demo route
(512x256), runs the engine in the real window (at that size, default 1600x1000),
curates a few loops and saves: main_window.png, frame_viewer.png, graph_view.png,
similarity_matrix.png, pair_view.png, loop_table.png, parameters.png,
evaluation.png and graph_view_layout.png (the graph without ground truth).
With ``PANOTOPO_SHOT_ROOT=1`` (set by packaging/xvfb_screenshots.sh) the main
window is also captured from the X server's screen (``import -window root``), as a
person would see it, into screen.png.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path


def make_screenshots(out_dir: str, route: str = "demo", method: str = "verified",
                     work_dir: str | None = None, size: tuple[int, int] = (1600, 1000)) -> list[Path]:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtCore import QEventLoop, QSettings
    from PySide6.QtWidgets import QApplication

    from engine.synth import make_recording, write_recording

    from .main_window import MainWindow

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(work_dir or tempfile.mkdtemp(prefix="panotopo-shots-"))
    rec = make_recording(route=route, look="indoor", width=512, height=256)
    paths = write_recording(rec, work, formats=("video", "poses"))

    app = QApplication.instance() or QApplication(["panotopo"])
    settings = QSettings(str(work / "settings.ini"), QSettings.IniFormat)
    w = MainWindow(settings=settings, interactive=False)
    w.setGeometry(0, 0, *size)
    # The default method, as a user sees it on first run (pass "ours" for more candidates).
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData(method))
    w.show()
    app.processEvents()
    loop = QEventLoop()
    w.mapReady.connect(loop.quit)
    w.runFailed.connect(lambda m: (print(m, file=sys.stderr), loop.quit()))
    if not w.open_path(str(paths["video"])):
        raise SystemExit(f"cannot open {paths['video']}")
    loop.exec()
    if not w.doc.has_map:
        raise SystemExit("the run failed")

    # Curate a little so every status shows: confirm the first true loop, reject a
    # false one (by ground truth), add a missed loop by hand, name two places.
    ev = w.doc.evaluation
    truth = ev.loop_truth if ev is not None else {}
    rows = w.doc.loop_rows()
    w.advance_after_decision = False
    true_rows = [r for r in rows if truth.get((r.u, r.v)) == "TP"]
    false_rows = [r for r in rows if truth.get((r.u, r.v)) == "FP"]
    if true_rows:
        w.loop_table.select_key(true_rows[0].key)
        w.decide("confirmed")
    if false_rows:
        w.loop_table.select_key(false_rows[0].key)
        w.decide("rejected")
    if ev is not None and ev.fn_pairs:
        i, j = ev.fn_pairs[len(ev.fn_pairs) // 2]
        w.add_manual_loop(w.doc.key_of_nodes(i, j))
    frames = w.doc.node_frames()
    if frames.size > 10:
        w.set_label(int(frames[0]), "start")
        w.set_label(int(frames[frames.size // 2]), "corridor B")
    pending = [r for r in w.doc.loop_rows() if r.status == "auto"]
    if pending or rows:
        w.loop_table.select_key((pending or rows)[0].key)
    w.frame_viewer.show_frame(w.frame_viewer.current_frame)

    def settle() -> None:
        for _ in range(10):
            app.processEvents()

    settle()
    wait_until = time.monotonic() + 60   # the pair view's feature matches, computed in the background
    while w.pair_view._pending and time.monotonic() < wait_until:
        app.processEvents()
        time.sleep(0.05)
    settle()
    saved = []

    def save(widget, name: str) -> None:
        path = out / name
        widget.grab().save(str(path))
        _shrink_png(path)
        saved.append(path)

    if os.environ.get("PANOTOPO_SHOT_ROOT"):
        import subprocess

        subprocess.run(["import", "-window", "root", str(out / "screen.png")], check=True)
        _shrink_png(out / "screen.png")
        saved.append(out / "screen.png")
    save(w, "main_window.png")
    save(w.frame_viewer, "frame_viewer.png")
    save(w.graph_view, "graph_view.png")
    save(w.pair_view, "pair_view.png")
    save(w.loop_table, "loop_table.png")
    w.tabs.setCurrentWidget(w.similarity_view)
    settle()
    save(w.similarity_view, "similarity_matrix.png")
    w.tabs.setCurrentWidget(w.graph_view)
    save(w.params_panel, "parameters.png")
    save(w.eval_panel, "evaluation.png")
    w.doc.set_poses(None, None)  # the graph as it looks without ground truth
    settle()
    save(w.graph_view, "graph_view_layout.png")
    w.undo_stack.setClean()
    w._extra_dirty = False
    w.close()
    return saved


# Pictures for the docs stay small: over this size a PNG is stored with a 256-colour palette.
MAX_PNG_BYTES = 300_000


def _shrink_png(path: Path) -> None:
    """Re-save ``path`` with a 256-colour palette when it is over ``MAX_PNG_BYTES``."""
    if path.stat().st_size <= MAX_PNG_BYTES:
        return
    from PIL import Image

    with Image.open(path) as img:
        small = img.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    small.save(path, optimize=True)


if __name__ == "__main__":
    shot_size = tuple(int(v) for v in sys.argv[2].split("x")) if len(sys.argv) > 2 else (1600, 1000)
    for p in make_screenshots(sys.argv[1] if len(sys.argv) > 1 else "docs/screenshots", size=shot_size):
        print(p)
