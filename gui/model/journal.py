"""Decision records: what a write-through journal stores, one per decision, and their replay.

A record is a small JSON-ready dict:

* ``{"op": "status", "frames": [a, b], "status": s}``: a loop's status set (a reset too);
* ``{"op": "manual", "frames": [a, b], "yaw": y|None}``: a manual loop added;
* ``{"op": "remove", "frames": [a, b]}``: a manual loop removed;
* ``{"op": "label", "frame": f, "label": text}``: a place named ("" clears it).

In a site (several recordings) every record also names the recordings: ``"sessions":
[sa, sb]`` beside a loop's ``frames`` and ``"session": s`` beside a label's ``frame``
(each frame a source frame of its own recording), as ``TopoMap.decisions()`` keys a site's
decisions; without them a record belongs to one recording.

Undo writes the record of the state it returns to, so replaying records in order
always ends in the state the user last saw. ``replay`` folds records into a
``TopoMap.decisions()`` dict, which ``TopoMap.apply_decisions`` applies to any map of
the recording (whichever way it is reopened).
"""

from __future__ import annotations

import copy
from typing import Iterable, Optional, Sequence

from engine.errors import InputError

from .loop_key import LoopKey, address_item, address_key

# Statuses that are no decision (the detection's own tiers): a record with one clears the decision.
NO_DECISION = ("auto", "candidate")
RECORD_STATUSES = ("candidate", "auto", "confirmed", "rejected", "manual")
OPS = ("status", "manual", "remove", "label")


# Longest recording name a record may carry (a file name, or a path where two names clash).
SESSION_MAX = 4096


def status(key: LoopKey, value: str, sessions: Optional[Sequence[str]] = None) -> dict:
    return {"op": "status", **address_item(key, sessions), "status": str(value)}


def manual(key: LoopKey, yaw: Optional[float] = None, value: str = "manual",
           sessions: Optional[Sequence[str]] = None) -> dict:
    record = {"op": "manual", **address_item(key, sessions), "yaw": None if yaw is None else float(yaw)}
    if value != "manual":
        record["status"] = value
    return record


def removed(key: LoopKey, sessions: Optional[Sequence[str]] = None) -> dict:
    return {"op": "remove", **address_item(key, sessions)}


def label(frame: int, text: str, session: Optional[str] = None) -> dict:
    record = {"op": "label", "frame": int(frame), "label": str(text)}
    if session is not None:
        record["session"] = str(session)
    return record


def _label_key(item: dict) -> tuple:
    return (item.get("session"), int(item["frame"]))


def replay(records: Iterable[dict], decisions: Optional[dict] = None) -> dict:
    """``decisions`` (a ``TopoMap.decisions()`` dict, e.g. the saved session's) with ``records`` applied in order."""
    out = copy.deepcopy(decisions or {})
    loops = {address_key(d["frames"], d.get("sessions")): d for d in out.get("loops", [])}
    manual_loops = {address_key(d["frames"], d.get("sessions")): d for d in out.get("manual", [])}
    labels = {_label_key(d): d for d in out.get("labels", [])}
    for record in records:
        op = record.get("op")
        if op == "label":
            where = _label_key(record)
            if record.get("label"):
                item = {"frame": int(record["frame"]), "label": str(record["label"])}
                if record.get("session") is not None:
                    item["session"] = str(record["session"])
                labels[where] = item
            else:
                labels.pop(where, None)
            continue
        key = address_key(record["frames"], record.get("sessions"))
        where = address_item(record["frames"], record.get("sessions"))
        if op == "status":
            if record["status"] in NO_DECISION:
                loops.pop(key, None)
            elif key in manual_loops and record["status"] == "manual":
                pass
            else:
                loops[key] = {**where, "status": str(record["status"])}
        elif op == "manual":
            manual_loops[key] = {**where, "yaw": record.get("yaw")}
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
        out = {"op": op, "frame": f._frame(record.get("frame"), "frame"), "label": text}
        if record.get("session") is not None:
            out["session"] = _session(record["session"], "session")
        return out
    out = {"op": op, "frames": f._frames(record.get("frames"), "frames")}
    if record.get("sessions") is not None:
        names = record["sessions"]
        if not isinstance(names, list) or len(names) != 2:
            raise f._fail("sessions", "two recording names", names)
        out["sessions"] = [_session(n, "sessions") for n in names]
    if op == "status" or (op == "manual" and "status" in record):
        if record.get("status") not in RECORD_STATUSES:
            raise f._fail("status", f"one of {', '.join(RECORD_STATUSES)}", record.get("status"))
        out["status"] = record["status"]
    if op == "manual":
        out["yaw"] = f._optional_number(record.get("yaw"), "yaw")
    return out


def _session(value, name: str) -> str:
    from engine import session_fields as f

    if not isinstance(value, str) or not value or len(value) > SESSION_MAX:
        raise f._fail(name, "a recording's name", value)
    return value


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
