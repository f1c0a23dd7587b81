"""A process that journals decisions until it is killed (used by test_journal_kill.py and
benchmarks/kill_test.py; not a test itself).

``python tests/journal_writer.py SESSION_PATH PERIOD_S`` opens the journal of SESSION_PATH,
then every PERIOD_S seconds appends ``{"decision": n}`` (n continuing after the last one
already in the journal) and, only once ``append`` has returned, prints ``ack n`` on stdout.
An acknowledged decision is one the app would have shown the user as made.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from engine.journal import Journal  # noqa: E402
from tests.child_lines import say  # noqa: E402


def main() -> None:
    session, period = sys.argv[1], float(sys.argv[2])
    journal = Journal.open(session)
    n = max((r["decision"] for r in journal.replay()), default=0)
    say("ready")
    while True:
        n += 1
        journal.append({"decision": n, "frames": [n, n + 100], "status": "confirmed"})
        say(f"ack {n}")
        time.sleep(period)


if __name__ == "__main__":
    main()
