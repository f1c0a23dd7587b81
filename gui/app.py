"""Entry points of the desktop app: ``main(argv)`` and ``run(input_path, screenshot)``.

``panotopo gui [INPUT] [--screenshot PNG]`` calls ``run``. With a screenshot path the
app runs without dialogs: it opens INPUT, runs the engine, selects the first loop
candidate so every view is filled, saves the window picture and exits.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Optional


def _ensure_platform(headless: bool) -> None:
    # No display (CI, ssh): draw offscreen. Must happen before Qt is imported.
    if headless and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def _quiet_offscreen_warnings() -> None:
    """The offscreen platform warns about every window resize; keep stderr for real messages."""
    from PySide6.QtCore import qInstallMessageHandler

    def handler(mode, context, message: str) -> None:
        if "propagateSizeHints" not in message:
            sys.stderr.write(message + "\n")

    if os.environ.get("QT_QPA_PLATFORM") == "offscreen":
        qInstallMessageHandler(handler)


def run(input_path, screenshot: Optional[str]) -> int:
    """Open the window (and INPUT: a path, or a list of paths opened together as one site);
    with ``screenshot``, save a picture and return."""
    _ensure_platform(screenshot is not None)
    from PySide6.QtCore import QEventLoop, QTimer
    from PySide6.QtWidgets import QApplication

    from .main_window import MainWindow

    _quiet_offscreen_warnings()
    app = QApplication.instance() or QApplication([sys.argv[0] if sys.argv else "panotopo"])
    app.setApplicationName("panotopo")
    app.setOrganizationName("panotopo")
    try:
        import resources

        app.setDesktopFileName(resources.DESKTOP_FILE_NAME)  # Wayland app id / X11 class: the .desktop entry
    except ImportError:
        pass
    window = MainWindow(interactive=screenshot is None)
    if screenshot is not None:
        ui = window.defaults["ui"]
        window.resize(int(ui.get("screenshot_width", 1600)), int(ui.get("screenshot_height", 1000)))
        from .window_layout import fit_to_screen

        if app.platformName() != "offscreen":   # a real screen (Xvfb): a picture of what fits on it
            fit_to_screen(window)
    window.show()

    if screenshot is None:
        if input_path:
            QTimer.singleShot(0, lambda: _open(window, input_path))
        return app.exec()

    status = 0
    try:
        if input_path:
            if not _open(window, input_path):
                if not window._last_error:  # otherwise the window has printed the reason already
                    print(f"panotopo: cannot open {input_path}", file=sys.stderr)
                return 2
            if window.runner.running:
                loop = QEventLoop()
                outcome: dict = {}
                window.mapReady.connect(lambda: (outcome.setdefault("ok", True), loop.quit()))
                window.runFailed.connect(lambda m: (outcome.setdefault("error", m), loop.quit()))
                window.runCancelled.connect(lambda: (outcome.setdefault("error", "run cancelled"), loop.quit()))
                loop.exec()
                if "error" in outcome:  # the window printed the reason (non-interactive)
                    if outcome["error"] == "run cancelled":
                        print("panotopo: run cancelled", file=sys.stderr)
                    return 2
            window.select_first_loop()
        for _ in range(5):  # let layouts and pyqtgraph settle before the picture
            app.processEvents()
        if not window.grab().save(screenshot):
            print(f"panotopo: cannot write {screenshot}", file=sys.stderr)
            status = 2
    finally:
        window.undo_stack.setClean()
        window._extra_dirty = False
        window.close()
    return status


def _open(window, input_path) -> bool:
    if isinstance(input_path, (list, tuple)):
        return window.open_paths(list(input_path))
    return window.open_path(input_path)


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="panotopo-gui", description="panotopo desktop app")
    parser.add_argument("input", nargs="*", help="recording, bag, folder, session (.json), descriptors (.npz) "
                        "or site map (.graphml); several: one site of them")
    parser.add_argument("--screenshot", metavar="PNG", help="run, save a picture of the window and exit")
    args = parser.parse_args(argv)
    inputs = list(args.input or [])
    return run(inputs if len(inputs) > 1 else (inputs[0] if inputs else None), args.screenshot)


if __name__ == "__main__":
    sys.exit(main())
