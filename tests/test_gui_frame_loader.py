"""Viewer frames decoded off the UI thread: the newest request wins, nothing is left running."""

from __future__ import annotations

import threading
import time

import pytest

pytest.importorskip("pytestqt")

from engine.sources import VideoSource  # noqa: E402
from gui.frame_cache import FrameCache  # noqa: E402
from gui.frame_loader import FrameLoader  # noqa: E402

SEEK_S = 0.05   # a slow seek, as in a long 4K H.264 video


class SlowVideo(VideoSource):
    """A real video whose reads take a while and remember the thread they ran on."""

    def __init__(self, path) -> None:
        super().__init__(path)
        self.reads: list[tuple[int, int]] = []   # (frame, thread id)

    def frame_at(self, index: int):
        self.reads.append((int(index), threading.get_ident()))
        time.sleep(SEEK_S)
        return super().frame_at(index)


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    from engine.synth import make_recording, write_recording

    out = tmp_path_factory.mktemp("loader")
    rec = make_recording(route="loop", look="indoor", width=256, height=128, fps=2.0, max_frames=40)
    return write_recording(rec, out, formats=("video",))["video"]


def test_requests_made_while_decoding_replace_each_other(qtbot, video):
    source = SlowVideo(video)
    loader = FrameLoader(FrameCache(source))
    loaded = []
    loader.loaded.connect(loaded.append)
    with qtbot.waitSignal(loader.loaded, timeout=10_000, check_params_cb=lambda i: i == 30):
        for index in (3, 10, 20, 30):   # a slider dragged across the timeline
            loader.request(index)
    loader.wait()
    main = threading.get_ident()
    assert all(thread != main for _, thread in source.reads)
    # At most the first request was decoded before the newest: 10 and 20 were replaced
    # while a decode (or the thread's start) was under way.
    frames = [frame for frame, _ in source.reads]
    assert frames[-1] == 30 and set(frames) <= {3, 30} and len(frames) == len(set(frames))
    assert loaded == frames and loader.cache.peek(30) is not None
    source.close()


def test_the_viewer_shows_where_the_slider_rests_without_decoding_on_the_ui_thread(qtbot, video, tmp_path):
    from pathlib import Path

    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication

    from gui.main_window import MainWindow

    w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), interactive=False)
    qtbot.addWidget(w)
    source = SlowVideo(video)
    w.doc.set_source(Path(video), source)      # the viewer shows frame 0 at once
    viewer = w.frame_viewer
    assert viewer.current_frame == 0
    source.reads.clear()
    for value in (5, 12, 25):                   # dragged: each value replaces the last
        viewer.slider.setValue(value)
        QApplication.processEvents()
    qtbot.waitUntil(lambda: viewer.current_frame == 25, timeout=10_000)
    assert source.reads and all(thread != threading.get_ident() for _, thread in source.reads)
    assert source.reads[-1][0] == 25 and len(source.reads) <= 3
    assert "frame 25" in viewer.info.text().replace("<b>", "").replace("</b>", "")
    w.shutdown()                                # waits for the decode thread, closes the source


def test_playback_moves_on_and_stops_at_the_end(qtbot, video, tmp_path):
    from pathlib import Path

    from PySide6.QtCore import QSettings

    from gui.main_window import MainWindow

    w = MainWindow(settings=QSettings(str(tmp_path / "s.ini"), QSettings.IniFormat), interactive=False)
    qtbot.addWidget(w)
    source = VideoSource(video)
    w.doc.set_source(Path(video), source)
    viewer = w.frame_viewer
    viewer.speed.setCurrentIndex(viewer.speed.findData(10.0))
    viewer.show_frame(source.frame_count - 6)
    viewer.toggle_play()
    assert viewer._play_timer.isActive()
    qtbot.waitUntil(lambda: viewer.current_frame == source.frame_count - 1, timeout=10_000)
    qtbot.waitUntil(lambda: not viewer._play_timer.isActive(), timeout=5_000)
    w.shutdown()
