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

from engine.errors import InputError

from .loop_key import LoopKey, frames_key

# Statuses that are no decision (the detection's own tiers): a record with one clears the decision.
NO_DECISION = ("auto", "candidate")
RECORD_STATUSES = ("candidate", "auto", "confirmed", "rejected", "manual")
OPS = ("status", "manual", "remove", "label")


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


def check_record(record) -> dict:
    """``record`` checked like a session field (``engine.session_fields``): its op, frames,
    status, yaw and label; InputError naming what is wrong. A record is data read back
    from disk: it may have been damaged or edited."""
    from engine import session_fields as f

    if not isinstance(record, dict):
        raise f._fail("record", "a mapping", record)
    op = record.get("op")
    if op not in OPS:
        raise f._fail("op", f"one of {', '.join(OPS)}", op)
    if op == "label":
        text = record.get("label")
        if not isinstance(text, str) or len(text) > f.LABEL_MAX:
            raise f._fail("label", f"a text of at most {f.LABEL_MAX} characters", text)
        return {"op": op, "frame": f._frame(record.get("frame"), "frame"), "label": text}
    out = {"op": op, "frames": f._frames(record.get("frames"), "frames")}
    if op == "status" or (op == "manual" and "status" in record):
        if record.get("status") not in RECORD_STATUSES:
            raise f._fail("status", f"one of {', '.join(RECORD_STATUSES)}", record.get("status"))
        out["status"] = record["status"]
    if op == "manual":
        out["yaw"] = f._optional_number(record.get("yaw"), "yaw")
    return out


def replay_checked(records: Iterable, decisions: Optional[dict] = None) -> tuple[dict, int]:
    """``replay`` of the records that pass ``check_record``; (decisions, records skipped).

    The result passes the session's own checks, so a session saved from it loads again.
    """
    good, skipped = [], 0
    for record in records:
        try:
            good.append(check_record(record))
        except InputError:
            skipped += 1
    return replay(good, decisions), skipped
