"""The one exception type a user sees.

Every bad input (missing file, unreadable container, unknown topic, wrong aspect
ratio, corrupt frame, bad checkpoint...) raises ``InputError`` with a message a
user understands in one line. The CLI prints it and exits non-zero; the GUI shows
it in a message box.
"""


class PanotopoError(Exception):
    """Base class of every error panotopo raises on purpose."""


class InputError(PanotopoError):
    """The user's input cannot be used; the message says why, in one line."""


class Cancelled(PanotopoError):
    """A long run was cancelled by the user."""


class OutputError(InputError, OSError):
    """An output cannot be written there (it is an input, not a regular file, a full disk...).

    Also an OSError, so that callers written for the OS's own write errors (the app's save
    and autosave) handle it the same way; the message names the user's file."""

    def __init__(self, message: str):
        InputError.__init__(self, message)
        self.filename = None
        self.strerror = None

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
