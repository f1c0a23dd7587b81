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
