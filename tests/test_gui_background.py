"""Blocking calls run off the UI thread, with their result or error handed back."""

import threading

import pytest

from engine.errors import InputError


@pytest.fixture()
def widget(qtbot):
    from PySide6.QtWidgets import QWidget

    w = QWidget()
    qtbot.addWidget(w)
    return w


def test_value_comes_back_and_the_call_ran_on_another_thread(widget):
    from gui.background import call_in_background

    ui_thread = threading.get_ident()
    value = call_in_background(widget, "working", lambda: threading.get_ident())
    assert value != ui_thread


def test_slow_call_keeps_the_event_loop_running(widget, qtbot):
    from PySide6.QtCore import QTimer

    from gui.background import call_in_background

    ticks = []
    timer = QTimer()
    timer.timeout.connect(lambda: ticks.append(1))
    timer.start(10)
    done = threading.Event()
    call_in_background(widget, "working", lambda: done.wait(0.5))
    timer.stop()
    assert len(ticks) >= 5  # the UI thread kept processing events while waiting


def test_errors_are_raised_in_the_caller(widget):
    from gui.background import call_in_background

    def bad():
        raise InputError("broken.mp4: unreadable or unsupported video container")

    with pytest.raises(InputError, match="unreadable"):
        call_in_background(widget, "working", bad)



def test_the_app_has_one_background_mechanism():
    """Issue 41, item 6: four thread mechanisms (a QObject worker on a QThread, two QThread
    subclasses, a ThreadPoolExecutor) became one: gui.background.Worker."""
    from pathlib import Path

    gui = Path(__file__).resolve().parent.parent / "gui"
    for path in gui.rglob("*.py"):
        if path.name == "background.py":
            continue
        text = path.read_text(encoding="utf-8")
        for other in ("QThread", "ThreadPoolExecutor", "threading.Thread(", "moveToThread"):
            assert other not in text, f"{path.name} starts threads of its own ({other})"


def test_newest_request_wins_cancel_drops_and_stop_ends_the_thread(qtbot):
    from gui.background import Worker

    worker = Worker()
    got, gate = [], threading.Event()
    worker.submit(lambda: gate.wait(5) and "first", got.append)
    worker.submit(lambda: "replaced", got.append)          # waits, then is replaced
    worker.submit(lambda: "newest", got.append)
    gate.set()
    assert worker.wait(10_000)
    assert got == ["newest"], "only the newest request's result is delivered"
    seen = []
    worker.submit(lambda job: job.cancel.wait(5) and "cancelled", seen.append, takes_job=True)
    worker.cancel()
    assert worker.wait(10_000) and seen == []
    worker.stop()
    assert all(not t.isRunning() for t in worker._threads)


def test_a_remap_job_works_on_a_copy_of_the_decisions():
    """Issue 41, item 6: the worker read the live decisions and a manual loop added meanwhile
    raised 'changed size during iteration' (retried on the exception's text)."""
    from tests.gui_maps import make_doc

    doc = make_doc(None, [(2, 15, "auto")], n=30)
    topomap = doc.topomap
    job = doc.remap_job(lambda: make_doc(None, [(2, 15, "auto")], n=30).topomap)
    doc.set_loop_status(doc.loop_rows()[0].key, "confirmed")   # decided while the job waits
    prepared = job()
    assert prepared.topomap is not topomap
    assert not doc.is_current(prepared), "made from the decisions of before: the window asks again"
    assert prepared.topomap.decisions()["loops"] == [], "the snapshot, not the live decisions"
