"""Decision records: what a write-through journal stores, one per decision, and their replay.

A record is a small JSON-ready dict:

* ``{"op": "status", "frames": [a, b], "status": s}``: a loop's status set (a reset too);
* ``{"op": "manual", "frames": [a, b], "yaw": y|None}``: a manual loop added;
* ``{"op": "remove", "frames": [a, b]}``: a manual loop removed;
* ``{"op": "label", "frame": f, "label": text}``: a place named ("" clears it).

Undo writes the record of the state it returns to, so replaying records in order
always ends in the state the user last saw. ``replay`` folds records into a
``TopoMap.decisions()`` dict, which ``TopoMap.apply_decisions`` applies to any map of
the recording (whichever way it is reopened).
"""

from __future__ import annotations

import copy
from typing import Iterable, Optional

from .loop_key import LoopKey, frames_key

# Statuses that are no decision (the detection's own tiers): a record with one clears the decision.
NO_DECISION = ("auto", "candidate")


def status(key: LoopKey, value: str) -> dict:
    return {"op": "status", "frames": [int(key[0]), int(key[1])], "status": str(value)}


def manual(key: LoopKey, yaw: Optional[float] = None, value: str = "manual") -> dict:
    record = {"op": "manual", "frames": [int(key[0]), int(key[1])], "yaw": None if yaw is None else float(yaw)}
    if value != "manual":
        record["status"] = value
    return record


def removed(key: LoopKey) -> dict:
    return {"op": "remove", "frames": [int(key[0]), int(key[1])]}


def label(frame: int, text: str) -> dict:
    return {"op": "label", "frame": int(frame), "label": str(text)}


def replay(records: Iterable[dict], decisions: Optional[dict] = None) -> dict:
    """``decisions`` (a ``TopoMap.decisions()`` dict, e.g. the saved session's) with ``records`` applied in order."""
    out = copy.deepcopy(decisions or {})
    loops = {frames_key(d["frames"]): d for d in out.get("loops", [])}
    manual_loops = {frames_key(d["frames"]): d for d in out.get("manual", [])}
    labels = {int(d["frame"]): d for d in out.get("labels", [])}
    for record in records:
        op = record.get("op")
        if op == "label":
            frame = int(record["frame"])
            if record.get("label"):
                labels[frame] = {"frame": frame, "label": str(record["label"])}
            else:
                labels.pop(frame, None)
            continue
        key = frames_key(record["frames"])
        if op == "status":
            if record["status"] in NO_DECISION:
                loops.pop(key, None)
            elif key in manual_loops and record["status"] == "manual":
                pass
            else:
                loops[key] = {"frames": list(key), "status": str(record["status"])}
        elif op == "manual":
            manual_loops[key] = {"frames": list(key), "yaw": record.get("yaw")}
            loops.pop(key, None)
        elif op == "remove":
            manual_loops.pop(key, None)
    return {"loops": list(loops.values()), "manual": list(manual_loops.values()), "labels": list(labels.values())}
