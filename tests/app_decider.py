"""A process that curates through the app model until it is killed (used by
test_journal_kill.py; not a test itself).

``python tests/app_decider.py SESSION_PATH PERIOD_S`` opens a map of ``LOOPS`` candidate loops
in the Qt-free app model (``gui.model``, what the window runs), attaches the recording's
journal exactly as the window does, replays what the journal already holds, then every
PERIOD_S seconds confirms the next undecided candidate through the review queue and, once
the decision call has returned, prints ``ack n`` (n = the candidate's number). An
acknowledged decision is one the window would have shown the user as made.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import networkx as nx

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from engine.graph import TopoMap  # noqa: E402
from engine.journal import Journal  # noqa: E402
from gui.model import MapDocument, ReviewQueue  # noqa: E402
from gui.model import journal as records  # noqa: E402
from tests.child_lines import say  # noqa: E402

LOOPS = 900
SPAN = 1000


def candidate_map() -> TopoMap:
    """Nodes at frames 10 k; candidate loop n joins nodes n and n + SPAN."""
    g = nx.Graph()
    for k in range(LOOPS + SPAN):
        g.add_node(f"n{k}", index=k, frame=10 * k, stamp=float(k), shift=0, label="")
        if k:
            g.add_edge(f"n{k - 1}", f"n{k}", kind="sequential", similarity=0.9, status="auto")
    for n in range(LOOPS):
        g.add_edge(f"n{n}", f"n{n + SPAN}", kind="loop", similarity=0.5, status="candidate",
                   tier="candidate", window_count=0, score=5.0)
    return TopoMap(g, {"method": "test"})


def key_of(n: int) -> tuple[int, int]:
    return (10 * n, 10 * (n + SPAN))


def main() -> None:
    session, period = sys.argv[1], float(sys.argv[2])
    journal = Journal.open(session)
    doc = MapDocument()
    doc.replace_map(candidate_map(), decisions=records.replay(journal.replay()))
    doc.journal = journal
    queue = ReviewQueue(doc)
    done = {r.key for r in doc.loop_rows() if r.status == "confirmed"}
    n = max((k[0] // 10 for k in done), default=-1)
    say("ready")
    while n + 1 < LOOPS:
        n += 1
        queue.decide_keys([key_of(n)], "confirmed")
        say(f"ack {n}")
        time.sleep(period)


if __name__ == "__main__":
    main()
