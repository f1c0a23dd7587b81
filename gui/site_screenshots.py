"""Pictures of the app with a site of three recordings open (docs/screenshots/site_*.png).

``python -m gui.site_screenshots docs/screenshots`` renders three days in one synthetic
world (``engine.synth.sessions.day_pair``: each day another light, start and direction),
writes them as videos, opens the three together in the real window (one site, as the
open dialog's multi-select does), curates loops across two of them, filters the review
queue by that pair of recordings and saves the window at 1280x720 (``site_1280x720.png``)
and at 1920x1080 (``site_large.png``). Run it under a real X server, as a person sees it:
``xvfb-run -s "-screen 0 1920x1080x24" python -m gui.site_screenshots docs/screenshots``.
Rendering and describing take a few minutes on two cores (the descriptors are cached in
the work folder, so the second size maps at once).
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from pathlib import Path

SIZES = {"site_1280x720.png": (1280, 720), "site_large.png": (1920, 1080)}


def write_days(work: Path) -> list[Path]:
    """Three recordings of one world on three days, as videos (rendered once per folder)."""
    from engine.synth.recording import write_recording
    from engine.synth.sessions import DayTwo, day_pair

    names = ("monday", "tuesday", "wednesday")
    paths = [work / f"{n}.mp4" for n in names]
    if all(p.is_file() for p in paths):
        return paths
    first = day_pair("loop", 0, width=512, height=256)
    other = day_pair("loop", 0, width=512, height=256,
                     day2=DayTwo(exposure=1.25, white_balance=(0.92, 1.0, 1.1), sun_turn=1.0, people=2,
                                 start_frac=0.55, back_frac=0.0, lane=0.15, speed=1.0))
    for name, rec in zip(names, (first.day1, first.day2, other.day2)):
        write_recording(dataclasses.replace(rec, route=name), work, formats=("video",))
    return paths


def shoot(paths: list[Path], work: Path, out: Path, name: str, size: tuple[int, int]) -> Path:
    from PySide6.QtCore import QEventLoop, QSettings
    from PySide6.QtWidgets import QApplication

    from .main_window import MainWindow

    app = QApplication.instance()
    w = MainWindow(settings=QSettings(str(work / "settings.ini"), QSettings.IniFormat),
                   cache_root=str(work / "cache"), interactive=False)
    w.setGeometry(0, 0, *size)
    w.show()
    app.processEvents()
    loop = QEventLoop()
    w.mapReady.connect(loop.quit)
    w.runFailed.connect(lambda m: (print(m, file=sys.stderr), loop.quit()))
    if not w.open_paths([str(p) for p in paths]):
        raise SystemExit("cannot open the site")
    loop.exec()
    if not w.doc.has_map:
        raise SystemExit("the run failed")
    names = w.doc.site.names
    pair = (names[0], names[1])
    w.advance_after_decision = False
    rows = sorted((r for r in w.doc.loop_rows() if r.sessions == pair), key=lambda r: -r.evidence)
    if len(rows) >= 3:   # a person's work across two recordings: two confirmed, one rejected
        for row, status in ((rows[0], "confirmed"), (rows[1], "confirmed"), (rows[-1], "rejected")):
            w.loop_table.select_key(row.key)
            w.decide(status)
    frames = w.doc.node_frames()
    if frames.size > 10:
        w.set_label(int(frames[frames.size // 3]), "corridor")
    w.loop_table.set_pair(pair)
    undecided = [r for r in rows if r.undecided]
    if undecided or rows:
        w.loop_table.select_key((undecided or rows)[0].key)
    deadline = time.monotonic() + 60   # the pair view's feature matches, computed in the background
    while w.pair_view._pending and time.monotonic() < deadline:
        app.processEvents()
        time.sleep(0.05)
    for _ in range(20):
        app.processEvents()
    path = out / name
    w.grab().save(str(path))
    from .screenshots import _shrink_png

    _shrink_png(path)
    w.undo_stack.setClean()
    w._extra_dirty = False
    w.close()
    return path


def make_site_screenshots(out_dir: str, work_dir: str | None = None) -> list[Path]:
    from PySide6.QtWidgets import QApplication

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(work_dir or tempfile.mkdtemp(prefix="panotopo-site-shots-"))
    work.mkdir(parents=True, exist_ok=True)
    paths = write_days(work)
    QApplication.instance() or QApplication(["panotopo"])
    saved = []
    for name, size in SIZES.items():
        for stale in work.glob("*.site*.graphml*"):   # each size opens the site afresh
            stale.unlink()
        saved.append(shoot(paths, work, out, name, size))
    return saved


if __name__ == "__main__":
    for p in make_site_screenshots(sys.argv[1] if len(sys.argv) > 1 else "docs/screenshots",
                                   sys.argv[2] if len(sys.argv) > 2 else None):
        print(p)
