"""The lines a forked writer (tests/journal_writer.py, tests/app_decider.py) says to its test."""

from __future__ import annotations

import os
import sys


def say(line: str) -> None:
    """One line on stdout in one write(2): a pipe write under PIPE_BUF is atomic, so a kill cannot
    leave half a line (print once wrote "ack 54" and its newline apart, and the test read "54exit")."""
    sys.stdout.flush()
    os.write(sys.stdout.fileno(), (line + "\n").encode())
