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

