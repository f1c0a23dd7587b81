"""Longest UI-thread stall while the app re-maps 20,000 cached nodes (issue 14: at most 100 ms).

A descriptors .npz of a random walk in 1024-D (every frame far enough from the last
to become a node) is opened in the real MainWindow with method ``ours``. Then a QTimer
heartbeat on the UI thread (every 5 ms) records the longest gap between its ticks while
the map parameters change a few times and the map is rebuilt (off the UI thread), shown
and its views refreshed. A gap is time the UI thread could not paint or take a key.

Run:  QT_QPA_PLATFORM=offscreen python benchmarks/bench_ui_stall.py [--nodes 20000] [--changes 3]
Prints one line per re-map and the longest gap overall.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import numpy as np  # noqa: E402


def random_walk_descriptors(path: Path, n: int, dim: int = 1024, seed: int = 0) -> Path:
    """``n`` frames whose 1024-D descriptors follow a random walk (consecutive cosine ~0.5)."""
    from engine.descriptors.base import Descriptors

    rng = np.random.default_rng(seed)
    vectors = np.empty((n, dim), np.float32)
    v = rng.normal(size=dim).astype(np.float32)
    for i in range(n):  # each step as long as the position: neighbours are distinct nodes
        v = v + rng.normal(size=dim).astype(np.float32) * np.linalg.norm(v) / np.sqrt(dim)
        v /= np.linalg.norm(v)
        vectors[i] = v
    Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                shifts=np.zeros(n, np.int64), vectors=vectors,
                meta={"descriptor": "effnet-vlad", "interval": 1.0, "shift": True}).save(path)
    return path


class Heartbeat:
    """A 5 ms QTimer on the UI thread; ``longest`` is the largest gap between two ticks,
    ``gaps`` every gap over 50 ms as (seconds since start, length)."""

    def __init__(self) -> None:
        from PySide6.QtCore import Qt, QTimer

        self.timer = QTimer()
        self.timer.setTimerType(Qt.PreciseTimer)
        self.timer.setInterval(5)
        self.timer.timeout.connect(self._tick)
        self.last = None
        self.longest = 0.0

    def start(self) -> None:
        self.last, self.longest, self.gaps = time.perf_counter(), 0.0, []
        self.started = self.last
        self.timer.start()

    def stop(self) -> float:
        self.timer.stop()
        self._tick()
        return self.longest

    def _tick(self) -> None:
        now = time.perf_counter()
        self.longest = max(self.longest, now - self.last)
        if now - self.last > 0.05:
            self.gaps.append((round(self.last - self.started, 2), round(now - self.last, 3)))
        self.last = now


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=20_000)
    parser.add_argument("--changes", type=int, default=3, help="parameter changes to time")
    args = parser.parse_args()

    from PySide6.QtCore import QEventLoop, QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from gui.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    tmp = Path(tempfile.mkdtemp(prefix="bench-ui-"))
    t0 = time.perf_counter()
    npz = random_walk_descriptors(tmp / "walk.npz", args.nodes)
    print(f"descriptors: {args.nodes} x 1024 random walk in {time.perf_counter() - t0:.1f} s")
    w = MainWindow(settings=QSettings(str(tmp / "s.ini"), QSettings.IniFormat), cache_root=str(tmp / "cache"),
                   interactive=False)
    w.params_panel.method.setCurrentIndex(w.params_panel.method.findData("ours"))
    w.resize(1280, 720)
    w.show()

    def wait_for_map(timeout_s: float = 600) -> float:
        loop = QEventLoop()
        w.mapReady.connect(loop.quit)
        w.runFailed.connect(loop.quit)
        QTimer.singleShot(int(timeout_s * 1000), loop.quit)
        start = time.perf_counter()
        loop.exec()
        w.mapReady.disconnect(loop.quit)
        w.runFailed.disconnect(loop.quit)
        return time.perf_counter() - start

    t0 = time.perf_counter()
    w.open_path(str(npz))
    wait_for_map()
    print(f"opened and mapped: {w.doc.node_count()} nodes, {len(w.doc.loop_rows())} loops "
          f"in {time.perf_counter() - t0:.1f} s")
    if w.doc.node_count() < 0.9 * args.nodes:
        print("warning: fewer nodes than frames; the walk is too smooth", file=sys.stderr)

    beat, worst = Heartbeat(), 0.0
    import gc
    gc_times, gc_start = [], {}

    def on_gc(phase, info):  # full collections stop every thread: count the long ones
        if phase == "start":
            gc_start["t"] = time.perf_counter()
        elif time.perf_counter() - gc_start.get("t", time.perf_counter()) > 0.03:
            gc_times.append((info["generation"], round(time.perf_counter() - gc_start["t"], 3)))

    gc.callbacks.append(on_gc)
    shown = w._remapped

    def timed_remapped(*a):  # how long swapping the new map in and refreshing the views takes
        t = time.perf_counter()
        shown(*a)
        print(f"  new map shown (UI thread) at {t - beat.started:.2f} s in {1000 * (time.perf_counter() - t):.0f} ms")

    w._remapped = timed_remapped
    for i in range(args.changes):
        for _ in range(20):
            app.processEvents()
        beat.start()
        spin = w.params_panel.neighbor_node_num
        spin.setValue(spin.value() + (1 if i % 2 == 0 else -1))   # what a spin-box click does
        took = wait_for_map()
        for _ in range(20):  # the repaint after the new map
            app.processEvents()
        gap = beat.stop()
        worst = max(worst, gap)
        if gc_times:
            print(f"  garbage collections over 30 ms (generation, s): {gc_times}")
            gc_times.clear()
        print(f"re-map {i + 1}: {w.doc.node_count()} nodes, {len(w.doc.loop_rows())} loops, "
              f"{took:.2f} s to the new map, longest UI stall {1000 * gap:.0f} ms; gaps over 50 ms: {beat.gaps}")
    print(f"longest UI stall over {args.changes} re-maps of {w.doc.node_count()} nodes: {1000 * worst:.0f} ms")
    beat.start()  # the same heartbeat with the app idle: what the machine itself adds
    idle = QEventLoop()
    QTimer.singleShot(10_000, idle.quit)
    idle.exec()
    print(f"baseline, app idle for 10 s: longest gap {1000 * beat.stop():.0f} ms (machine load, not the app)")
    w.undo_stack.setClean()
    w.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
