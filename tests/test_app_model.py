"""The application model (gui.model) in plain Python: no Qt, no window.

Maps are made by hand (nodes and loop arcs with evidence), as the engine hands them
to the app: candidates waiting for a person, auto loops accepted by the engine.
"""

from __future__ import annotations

import random
from pathlib import Path

import networkx as nx
import numpy as np

from engine.graph import TopoMap
from engine.params import MapParams
from gui.model import MapDocument, ReviewQueue
from gui.model import journal
from gui.model.commands import SetLabel
from gui.model.document import needs_remap
from gui.model.keys import SHORTCUTS, bad_overrides, keys_for, readme_section, shortcut_table

ROOT = Path(__file__).resolve().parent.parent


def make_map(loops: list[dict], nodes: int = 700) -> TopoMap:
    """Nodes n0..n{nodes-1} at frames 10 k; ``loops``: dicts with a, b and edge attributes."""
    g = nx.Graph()
    for k in range(nodes):
        g.add_node(f"n{k}", index=k, frame=10 * k, stamp=float(k), shift=0, label="")
    for k in range(nodes - 1):
        g.add_edge(f"n{k}", f"n{k + 1}", kind="sequential", similarity=0.9, status="auto")
    for loop in loops:
        attrs = {k: v for k, v in loop.items() if k not in ("a", "b")}
        attrs.setdefault("kind", "loop")
        attrs.setdefault("similarity", 0.5)
        attrs.setdefault("window_count", 0)
        g.add_edge(f"n{loop['a']}", f"n{loop['b']}", **attrs)
    return TopoMap(g, {"method": "test"})


def candidates(good: int, bad: int, seed: int = 1) -> list[dict]:
    """``good`` true loops with strong evidence and ``bad`` look-alikes with weak evidence,
    shuffled along the route so node order says nothing about which is which."""
    rng = random.Random(seed)
    kinds = ["good"] * good + ["bad"] * bad
    rng.shuffle(kinds)
    out = []
    for i, kind in enumerate(kinds):
        score = rng.uniform(0.7, 0.99) if kind == "good" else rng.uniform(0.2, 0.6)
        inliers = rng.randint(60, 200) if kind == "good" else rng.randint(0, 20)
        out.append(dict(a=i, b=i + 350, status="candidate", score=score, inliers=inliers,
                        inlier_ratio=inliers / 250, support=0.5, truth=kind))
    return out


def open_doc(loops: list[dict], nodes: int = 700) -> tuple[MapDocument, ReviewQueue]:
    doc = MapDocument()
    doc.replace_map(make_map(loops, nodes))
    return doc, ReviewQueue(doc)


def statuses(doc: MapDocument) -> dict:
    return {r.key: r.status for r in doc.loop_rows()}


def test_300_candidates_are_decided_in_a_handful_of_actions_all_undoable():
    loops = candidates(good=250, bad=50)
    doc, queue = open_doc(loops)
    truth = {(10 * lp["a"], 10 * lp["b"]): lp["truth"] for lp in loops}
    ranked = queue.keys()
    assert [truth[k] for k in ranked[:250]] == ["good"] * 250   # the ranking puts the evidence first

    actions = 0
    weakest_good = ranked[249]                          # the user looks down the list to the last good one
    queue.select([weakest_good]); actions += 1
    assert queue.reject_below(queue.evidence_of(weakest_good)) == 50; actions += 1
    queue.select(queue.keys(statuses=("candidate", "auto"))); actions += 1    # "undecided" filter, Ctrl+A
    assert queue.decide("confirmed") == 250; actions += 1
    assert actions <= 5
    assert all(statuses(doc)[k] == ("confirmed" if t == "good" else "rejected") for k, t in truth.items())
    assert queue.next_undecided() is None
    assert len(doc.history) == 2                          # two bulk actions, two undo steps

    doc.history.undo()
    assert sorted(set(statuses(doc).values())) == ["candidate", "rejected"]
    doc.history.undo()
    assert set(statuses(doc).values()) == {"candidate"}
    doc.history.redo()
    doc.history.redo()
    assert all(statuses(doc)[k] == ("confirmed" if t == "good" else "rejected") for k, t in truth.items())


def test_a_repeated_decision_on_the_last_loop_never_reaches_another():
    """Defect 1: R R on the last loop rejected the first loop too (the selection wrapped)."""
    doc, queue = open_doc(candidates(good=4, bad=0))
    order = queue.keys()
    queue.select([order[-1]])
    queue.decide("rejected", order)
    queue.decide("rejected", order)
    assert queue.selected == [order[-1]]
    assert [statuses(doc)[k] for k in order] == ["candidate"] * 3 + ["rejected"]


def test_a_decision_advances_to_the_row_below_only():
    doc, queue = open_doc(candidates(good=3, bad=0))
    order = queue.keys()
    queue.select([order[0]])
    queue.decide("confirmed", order)
    assert queue.selected == [order[1]]
    assert statuses(doc)[order[1]] == "candidate"        # the advance decides nothing


def test_reset_takes_each_loop_back_to_its_own_tier_and_leaves_manual_loops_alone():
    doc, queue = open_doc([dict(a=0, b=100, status="candidate", score=0.8),
                           dict(a=1, b=200, status="auto", score=0.9),
                           dict(a=2, b=300, status="manual")])
    cand, auto, manual = (0, 1000), (10, 2000), (20, 3000)
    assert queue.decide_keys([cand, auto, manual], "rejected") == 2
    assert statuses(doc) == {cand: "rejected", auto: "rejected", manual: "manual"}
    queue.decide_keys([cand, auto], "auto")             # "reset"
    assert statuses(doc) == {cand: "candidate", auto: "auto", manual: "manual"}
    assert len(doc.history) == 2


def test_next_undecided_skips_decided_loops_and_wraps_without_deciding():
    doc, queue = open_doc(candidates(good=5, bad=0))
    order = queue.keys()
    queue.decide_keys([order[1], order[2]], "confirmed")
    assert queue.next_undecided(after=order[0]) == order[3]
    assert queue.next_undecided(after=order[4]) == order[0]   # wraps: it only moves the selection
    queue.decide_keys(order, "rejected")
    assert queue.next_undecided() is None


def test_filters_and_counts_per_status_and_kind():
    doc, queue = open_doc([dict(a=0, b=100, status="candidate"), dict(a=1, b=200, status="candidate"),
                           dict(a=2, b=300, status="auto"), dict(a=3, b=400, status="manual")])
    queue.decide_keys([(0, 1000)], "confirmed")
    counts = queue.counts()
    assert counts["status"]["candidate"] == 1 and counts["status"]["confirmed"] == 1
    assert counts["kind"] == {"candidate": 2, "auto": 1, "manual": 1}
    assert counts["undecided"]["undecided"] == 2
    assert queue.keys(kinds=("candidate",)) and all(doc.tier_of(k) == "candidate"
                                                    for k in queue.keys(kinds=("candidate",)))
    assert queue.keys(statuses=("manual",)) == [(30, 4000)]


def test_ranking_uses_score_then_inliers_and_falls_back_to_similarity():
    doc, queue = open_doc([dict(a=0, b=100, status="candidate", score=0.5, inliers=10),
                           dict(a=1, b=200, status="candidate", score=0.5, inliers=90),
                           dict(a=2, b=300, status="candidate", score=0.9)])
    assert queue.keys() == [(20, 3000), (10, 2000), (0, 1000)]
    doc2, queue2 = open_doc([dict(a=0, b=100, similarity=0.6), dict(a=1, b=200, similarity=0.8)])
    assert queue2.keys() == [(10, 2000), (0, 1000)]     # no score: similarity is the evidence


def test_decisions_carry_over_a_rebuilt_map_and_a_changed_parameter():
    loops = [dict(a=0, b=100, status="candidate", score=0.8), dict(a=1, b=200, status="auto", score=0.9)]
    doc, queue = open_doc(loops)
    queue.decide_keys([(0, 1000)], "confirmed")
    queue.decide_keys([(10, 2000)], "rejected")
    doc.push(SetLabel(50, "", "kitchen"))
    doc.replace_map(make_map(loops), decisions=doc.decisions())   # a re-run of the same recording
    assert statuses(doc) == {(0, 1000): "confirmed", (10, 2000): "rejected"}
    assert doc.label_of_frame(50) == "kitchen"
    assert doc.tier_of((0, 1000)) == "candidate"        # reset still knows where to go back to
    assert needs_remap(MapParams(loop_sim_th=0.5), MapParams(loop_sim_th=0.6))
    assert not needs_remap(MapParams(), MapParams())


def test_no_remap_across_methods_that_need_other_descriptors():
    """A method change is a remap only where both methods describe alike (shift and describe
    options): verified's standardised descriptors are no input for ours, nor simple's unshifted."""
    assert needs_remap(MapParams(method="ours"), MapParams(method="shift-simple"))
    assert not needs_remap(MapParams(method="verified"), MapParams(method="ours"))
    assert not needs_remap(MapParams(method="ours"), MapParams(method="verified"))
    assert not needs_remap(MapParams(method="ours"), MapParams(method="simple"))
    assert needs_remap(MapParams(method="verified"), MapParams(method="verified", auto_z=4.0))


def test_every_decision_is_one_record_and_replay_restores_the_work():
    loops = [dict(a=0, b=100, status="candidate"), dict(a=1, b=200, status="candidate"),
             dict(a=2, b=300, status="candidate")]
    doc, queue = open_doc(loops)
    records: list = []
    doc.journal = type("ListJournal", (), {"append": lambda self, r: records.append(r)})()
    queue.decide_keys([(0, 1000), (10, 2000)], "confirmed")
    queue.decide_keys([(20, 3000)], "rejected")
    doc.history.undo()                                  # undo is recorded too: the state it returns to
    from gui.model.commands import AddManualLoop
    doc.push(AddManualLoop((50, 6000)))
    doc.push(SetLabel(40, "", "door"))
    assert [r["op"] for r in records] == ["status", "status", "status", "status", "manual", "label"]

    fresh = MapDocument()                               # reopened after a crash: the map and the records
    fresh.replace_map(make_map(loops), decisions=journal.replay(records))
    assert statuses(fresh) == statuses(doc)
    assert fresh.label_of_frame(40) == "door"


def test_history_clean_state_and_redo_branch():
    doc, queue = open_doc(candidates(good=3, bad=0))
    order = queue.keys()
    assert doc.history.is_clean()
    queue.decide_keys([order[0]], "confirmed")
    doc.history.set_clean()
    queue.decide_keys([order[1]], "confirmed")
    assert not doc.history.is_clean()
    doc.history.undo()
    assert doc.history.is_clean() and doc.history.can_redo()
    queue.decide_keys([order[2]], "rejected")           # a new edit drops the redo branch
    assert not doc.history.can_redo() and not doc.history.is_clean()


def test_shortcut_overrides_and_their_mistakes():
    table = shortcut_table({"confirm": "Return", "reject": ["X", "Shift+X"], "reset": None,
                            "no_such_action": "Q", "frame_step": "A", "run": 5})
    assert keys_for("confirm", table) == ("Return",)
    assert keys_for("reject", table) == ("X", "Shift+X")
    assert keys_for("reset", table) == ()
    assert keys_for("frame_step", table) == keys_for("frame_step")   # fixed: a widget handles it
    assert keys_for("run", table) == ("F5",)                        # not a key: ignored
    assert sorted(bad_overrides({"no_such_action": "Q", "frame_step": "A", "run": 5, "confirm": "C"})) == [
        "frame_step", "no_such_action", "run"]


def test_no_two_actions_share_a_key():
    keys = [k for s in SHORTCUTS for k in s.keys]
    assert len(keys) == len(set(keys))


def test_the_readme_lists_exactly_the_shortcut_table():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert readme_section() in readme, "README key list is stale: paste gui.model.keys.readme_section()"
    listed = set()
    start = readme.index(readme_section().splitlines()[0])
    for line in readme[start:].splitlines()[4:]:
        if not line.startswith("|"):
            break
        listed |= {part.strip("` ") for part in line.split("|")[2].split(" or ")}
    assert listed == {k for s in SHORTCUTS for k in s.keys}


def test_the_engine_tier_and_confidence_drive_reset_and_rank():
    """A map whose decisions were made elsewhere (status confirmed, tier candidate): reset
    goes back to the engine's tier; the engine's confidence ranks before the raw score."""
    doc, queue = open_doc([dict(a=0, b=100, status="confirmed", tier="candidate", score=9.0, confidence=0.2),
                           dict(a=1, b=200, status="candidate", tier="candidate", score=3.0, confidence=0.9)])
    assert queue.keys() == [(10, 2000), (0, 1000)]
    queue.decide_keys([(0, 1000)], "auto")               # "reset"
    assert statuses(doc)[(0, 1000)] == "candidate"


def test_similarity_preview_keeps_a_thin_revisit_line_visible():
    from gui.model.similarity import floor_of, preview_of

    m = 5000
    matrix = np.zeros((m, m), np.float32)
    matrix[np.arange(1000), np.arange(3000, 4000)] = 0.9    # one revisit: a one-cell-wide diagonal
    preview = preview_of(matrix, side=512)
    assert max(preview.shape) <= 512
    assert preview.max() == np.float32(0.9)               # block maxima: the line survives
    assert (preview > 0.5).sum() >= 512 // 5 - 2           # ... along its whole length
    assert floor_of(matrix) == 0.0


def test_undo_after_a_remap_that_dropped_the_loop_keeps_the_decision_carried():
    loops = [dict(a=0, b=100, status="candidate"), dict(a=1, b=200, status="candidate")]
    doc, queue = open_doc(loops)
    queue.decide_keys([(0, 1000)], "rejected")
    doc.replace_map(make_map(loops[1:]), decisions=doc.decisions())   # new parameters: that loop is gone
    assert {"frames": [0, 1000], "status": "rejected"} in doc.decisions()["loops"]
    doc.history.undo()                                   # no error; the decision is taken back
    assert all(d["frames"] != [0, 1000] for d in doc.decisions()["loops"])
    doc.history.redo()
    assert {"frames": [0, 1000], "status": "rejected"} in doc.decisions()["loops"]
    doc.replace_map(make_map(loops), decisions=doc.decisions())       # the loop is back, decided
    assert statuses(doc)[(0, 1000)] == "rejected"


def test_a_journal_that_fails_to_write_keeps_the_decision_and_says_so():
    doc, queue = open_doc([dict(a=0, b=100, status="candidate")])

    class FullDisk:
        def append(self, record):
            raise OSError(28, "No space left on device")

    told: list = []
    doc.on("journalFailed", told.append)
    doc.journal = FullDisk()
    queue.decide_keys([(0, 1000)], "confirmed")
    assert statuses(doc)[(0, 1000)] == "confirmed"
    assert len(told) == 1 and "No space left" in told[0] and doc.journal is None


def test_undo_of_a_manual_loop_and_a_name_after_the_nodes_moved():
    doc, queue = open_doc([], nodes=60)
    from gui.model.commands import AddManualLoop
    doc.push(AddManualLoop((50, 400)))
    doc.push(SetLabel(50, "", "door"))
    moved = nx.relabel_nodes(make_map([], 60).graph, lambda n: n)   # same route, nodes 3 frames later
    for n, d in moved.nodes(data=True):
        d["frame"] += 3
    doc.replace_map(TopoMap(moved, {}), decisions=doc.decisions())
    assert [r.status for r in doc.loop_rows()] == ["manual"] and doc.label_of_frame(53) == "door"
    doc.history.undo()
    doc.history.undo()
    assert doc.loop_rows() == [] and doc.label_of_frame(53) == ""


def _descs(shift: bool = True):
    import numpy as np

    from engine.descriptors.base import Descriptors

    n = 12
    v = np.eye(n, 16, dtype=np.float32)
    return Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                       shifts=np.zeros(n, np.int64), vectors=v,
                       meta={"descriptor": "other-model", "interval": 1.0, "shift": shift})


def test_the_describe_or_remap_decision_is_made_in_the_model():
    """Issue 41, item 6: the window decided describe-or-remap itself; gui.model.run_plan does."""
    from engine.params import MapParams
    from engine.pipeline import DescribeSettings
    from gui.model import run_plan

    shifted, plain = _descs(True), _descs(False)
    ours, simple = MapParams(method="ours"), MapParams(method="simple")
    settings = DescribeSettings(descriptor="other-model")
    assert run_plan.plan_change(ours, None, settings, False, False).action == run_plan.WAIT
    assert run_plan.plan_change(ours, shifted, settings, False, True).action == run_plan.WAIT
    assert run_plan.plan_change(ours, shifted, settings, False, False).action == run_plan.REMAP
    assert run_plan.plan_change(simple, shifted, settings, False, False).action == run_plan.DESCRIBE
    refused = run_plan.plan_change(ours, plain, settings, True, False)
    assert refused.action == run_plan.REFUSE and "shifted" in refused.message
