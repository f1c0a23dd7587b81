"""Progress reporting and cancellation shared by the CLI, the GUI worker and tests.

A ``Progress`` callback receives ``(done, total, stage)``; ``total`` may be 0 when
unknown. A ``CancelToken`` is anything with ``is_set()`` (a ``threading.Event``
works). Long loops call ``check(cancel)`` between units of work.
"""

from __future__ import annotations

from typing import Callable, Optional, Protocol

from .errors import Cancelled

Progress = Callable[[int, int, str], None]


class CancelToken(Protocol):
    def is_set(self) -> bool: ...


def report(progress: Optional[Progress], done: int, total: int, stage: str) -> None:
    if progress is not None:
        progress(done, total, stage)


def check(cancel: Optional[CancelToken]) -> None:
    """Raise ``Cancelled`` when the user asked to stop."""
    if cancel is not None and cancel.is_set():
        raise Cancelled("cancelled by the user")
