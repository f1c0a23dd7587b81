"""panotopo desktop app (PySide6 + pyqtgraph). Imports engine; engine never imports this."""

from .qt_compat import protect_bools

try:
    protect_bools()  # before any signal is emitted (see gui/qt_compat.py)
except ImportError:  # no Qt at all (gui.model used on its own): nothing to protect
    pass
