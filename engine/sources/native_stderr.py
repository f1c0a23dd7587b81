"""Keep C libraries' own error lines off the user's terminal: ``native_messages_dropped``.

libpng prints "libpng error: ..." straight to file descriptor 2 when OpenCV decodes a damaged
PNG (OpenCV installs no error handler), and OpenCV logs its own "[ WARN:...]" / "[ERROR:...]"
lines when its log level was not set before it was imported, before panotopo's one-line reason. Python cannot
catch that line, so the decode runs with descriptor 2 pointed at a temporary file; afterwards
the lines that match ``prefixes`` are dropped and anything else written meanwhile (another
thread's output) is passed on to the real stderr, so nothing but the library's chatter is lost.
Calls are serialised by a lock (descriptor 2 is one per process).
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
from contextlib import contextmanager
from typing import Iterator

_LOCK = threading.Lock()


@contextmanager
def native_messages_dropped(prefixes: tuple[str, ...] = ("libpng ", "[ WARN:", "[ERROR:")) -> Iterator[None]:
    """Run the block with descriptor 2 captured; pass on what does not start with ``prefixes``
    (libpng's lines and OpenCV's own log lines about the same image)."""
    with _LOCK:
        try:
            sys.stderr.flush()
        except (AttributeError, ValueError, OSError):
            pass
        try:
            saved = os.dup(2)
        except OSError:   # no descriptor 2 (a windowed app): nothing can leak
            yield
            return
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(saved, 2)
                os.close(saved)
                sink.seek(0)
                kept = [line for line in sink.read().splitlines(keepends=True)
                        if not line.decode("utf-8", "replace").startswith(prefixes)]
                if kept:
                    os.write(2, b"".join(kept))
