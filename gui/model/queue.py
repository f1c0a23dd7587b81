"""The review queue: every detected loop in one list ranked by its evidence, walked by a person.

Candidates (found, not accepted) and auto loops (accepted automatically) are both
*undecided* until a person confirms or rejects them. The queue ranks them by evidence
(the engine's ``confidence`` where it gives one, else the calibrated ``score``, else
the cosine similarity; then inliers), filters and counts them by status and by kind (the tier detection gave
them: candidate, auto, manual), and applies decisions, alone or in bulk, each action
one undo step.

In a site (several recordings) the queue holds the loops within and across every
recording, and filters them by the pair of recordings they join (``pair``: ("A", "B")
for loops between A and B, ("A", "A") for A's own; ``pair_choices`` lists the pairs
with their counts, for a filter such as "A × B (3)").

The rule behind every decision: it applies to the loops that are *selected*
(``select``), which the window shows selected, and to nothing else. After a decision
the selection advances to the next row *below* in the order the user sees; after the
last row it stays where it is, so a repeated key never reaches a loop the user has
not seen (issue 14, defect 1).
"""

from __future__ import annotations

import math
from typing import Iterable, Optional, Sequence

from .commands import SetStatuses
from .document import DECIDED, STATUSES, UNDECIDED, LoopRow, MapDocument
from .loop_key import LoopKey

KINDS = ("candidate", "auto", "manual")
Pair = tuple[str, str]


def in_pair(row: LoopRow, pair: Optional[Pair]) -> bool:
    """Does ``row`` join the recordings of ``pair`` (either way round)? None: every row."""
    if pair is None:
        return True
    if row.sessions is None:
        return False
    return tuple(row.sessions) == tuple(pair) or tuple(row.sessions) == (pair[1], pair[0])


def pair_text(pair: Pair) -> str:
    return f"{pair[0]} × {pair[1]}"


def rank_key(row: LoopRow) -> tuple:
    """Best evidence first: confidence (else score, else similarity), then geometric inliers, then node order."""
    inliers = -1 if row.inliers is None else row.inliers
    return (-row.evidence, -inliers, row.index_u, row.index_v)


class ReviewQueue:
    """Ranking, filters, counts, selection and (bulk) decisions over a ``MapDocument``."""

    def __init__(self, doc: MapDocument) -> None:
        self.doc = doc
        self.selected: list[LoopKey] = []
        self.advance_after_decision = True

    # -- the list ---------------------------------------------------------------
    def rows(self, statuses: Optional[Iterable[str]] = None, kinds: Optional[Iterable[str]] = None,
             pair: Optional[Pair] = None) -> list[LoopRow]:
        """The loops ranked by evidence, only those with these statuses and kinds and (a site)
        between this pair of recordings (None: all)."""
        wanted_s = None if statuses is None else set(statuses)
        wanted_k = None if kinds is None else set(kinds)
        rows = [r for r in self.doc.loop_rows()
                if (wanted_s is None or r.status in wanted_s) and (wanted_k is None or r.tier in wanted_k)
                and in_pair(r, pair)]
        return sorted(rows, key=rank_key)

    def keys(self, statuses: Optional[Iterable[str]] = None, kinds: Optional[Iterable[str]] = None,
             pair: Optional[Pair] = None) -> list[LoopKey]:
        return [r.key for r in self.rows(statuses, kinds, pair)]

    def pair_choices(self) -> list[tuple[str, Optional[Pair], int, int]]:
        """The pair filter's choices: (text, pair, loops, undecided), "All recordings" (None)
        first, then every pair of recordings of the site in its order ([] for one recording)."""
        site = self.doc.site
        if site is None:
            return []
        counts: dict = {p: [0, 0] for p in site.pairs()}
        for r in self.doc.loop_rows():
            if r.sessions is not None:
                c = counts.setdefault(tuple(r.sessions), [0, 0])
                c[0] += 1
                c[1] += r.undecided
        total = sum(c[0] for c in counts.values())
        undecided = sum(c[1] for c in counts.values())
        return [("All recordings", None, total, undecided)] + [
            (pair_text(p), p, c[0], c[1]) for p, c in counts.items()]

    def counts(self) -> dict[str, dict[str, int]]:
        """{"status": {status: n}, "kind": {kind: n}, "undecided": {"undecided": n}} over every loop."""
        status = {s: 0 for s in STATUSES}
        kind = {k: 0 for k in KINDS}
        for r in self.doc.loop_rows():
            status[r.status] = status.get(r.status, 0) + 1
            kind[r.tier] = kind.get(r.tier, 0) + 1
        return {"status": status, "kind": kind, "undecided": {"undecided": sum(status[s] for s in UNDECIDED)}}

    # -- selection ---------------------------------------------------------------
    def select(self, keys: Iterable[LoopKey]) -> None:
        """What the user sees selected (the window keeps this in step with its table)."""
        known = {r.key for r in self.doc.loop_rows()}
        self.selected = [tuple(k) for k in keys if tuple(k) in known]

    def next_undecided(self, after: Optional[LoopKey] = None,
                       order: Optional[Sequence[LoopKey]] = None) -> Optional[LoopKey]:
        """The first undecided loop after ``after`` in ``order`` (default: the ranking), wrapping
        to the top; None when every loop is decided. Only moves the selection, decides nothing."""
        order = list(order) if order is not None else self.keys()
        status = {r.key: r.status for r in self.doc.loop_rows()}
        start = order.index(tuple(after)) + 1 if after is not None and tuple(after) in order else 0
        for key in order[start:] + order[:start]:
            if status.get(key) in UNDECIDED:
                return key
        return None

    @staticmethod
    def row_after(key: LoopKey, order: Sequence[LoopKey]) -> Optional[LoopKey]:
        """The row below ``key`` in ``order``; None after the last (never wraps, never goes back)."""
        order = list(order)
        if tuple(key) not in order:
            return None
        i = order.index(tuple(key)) + 1
        return order[i] if i < len(order) else None

    # -- decisions ---------------------------------------------------------------------
    def decide(self, status: str, order: Optional[Sequence[LoopKey]] = None) -> int:
        """Set ``status`` on every selected detected loop (manual ones are left alone), one undo step.

        "reset" is ``status`` "auto" or "candidate": each loop goes back to its own tier.
        With one loop selected and ``advance_after_decision``, the selection moves to the
        row below it in ``order`` (default: the ranking), or stays after the last row.
        Returns how many loops changed.
        """
        if status not in DECIDED + UNDECIDED:
            raise ValueError(f"not a decision: {status!r}")
        current = {r.key: r for r in self.doc.loop_rows()}
        old, new = {}, {}
        for key in self.selected:
            row = current.get(key)
            if row is None or row.status == "manual":
                continue
            target = row.tier if status in UNDECIDED else status
            if row.status != target:
                old[key], new[key] = row.status, target
        if new:
            self.doc.push(SetStatuses(old, new))
        if len(self.selected) == 1 and self.advance_after_decision and status in DECIDED:
            following = self.row_after(self.selected[0], order if order is not None else self.keys())
            if following is not None:
                self.selected = [following]
        return len(new)

    def decide_keys(self, keys: Iterable[LoopKey], status: str) -> int:
        """Select ``keys`` and decide them (one undo step); the selection stays on them."""
        self.select(keys)
        advance, self.advance_after_decision = self.advance_after_decision, False
        try:
            return self.decide(status)
        finally:
            self.advance_after_decision = advance

    def reject_below(self, threshold: float) -> int:
        """Reject every undecided loop whose evidence is below ``threshold`` (one undo step).

        The threshold is normally the evidence of the selected loop, which the user has
        judged good: everything ranked under it and still undecided goes. Returns how many.
        """
        rows = [r for r in self.doc.loop_rows() if r.undecided and r.evidence < threshold]
        if not rows:
            return 0
        old = {r.key: r.status for r in rows}
        new = {r.key: "rejected" for r in rows}
        self.doc.push(SetStatuses(old, new, f"Reject {len(rows)} loops ranked below {threshold:.3f}"))
        return len(rows)

    def evidence_of(self, key: LoopKey) -> float:
        for r in self.doc.loop_rows():
            if r.key == tuple(key):
                return r.evidence
        return -math.inf
