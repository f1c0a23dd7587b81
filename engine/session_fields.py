"""Checks of every field of a session file: a session is data, never trusted blindly.

A session file can come from anywhere (a colleague, a download, a crafted attack), so
every field is checked for type and range before the app or the engine sees it, with a
message naming the field: ``session field 'decisions.manual[3].frames': expected two
integers, got ['a', 'b']``. Descriptor options pass an allow-list
(``engine.validate.ALLOWED_OPTIONS``): nothing in a session can name a file to write.
Unknown keys are dropped (a newer panotopo may add some); wrong types are refused.
"""

from __future__ import annotations

import math
from typing import Any

from . import validate
from .errors import InputError

STATUSES = ("auto", "confirmed", "rejected", "manual")


def _fail(name: str, what: str, value: Any) -> InputError:
    text = repr(value)
    if len(text) > 80:
        text = text[:77] + "..."
    return InputError(f"session field '{name}': expected {what}, got {text}")


def _mapping(value: Any, name: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _fail(name, "a mapping", value)
    return value


def _list(value: Any, name: str) -> list:
    if not isinstance(value, list):
        raise _fail(name, "a list", value)
    return value


def _frame(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _fail(name, "a frame number (an integer >= 0)", value)
    return value


def _frames(value: Any, name: str) -> list[int]:
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        raise _fail(name, "two integers", value)
    return [_frame(v, name) for v in value]


def _optional_number(value: Any, name: str):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(name, "a finite number or null", value)
    return float(value)


def check_version(value: Any, newest: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail("version", "an integer", value)
    if value > newest:
        raise InputError(f"session version {value} is newer than this panotopo understands "
                         f"(it reads up to {newest}); update panotopo")
    if value < 1:
        raise _fail("version", f"1 to {newest}", value)
    return value


def check_decisions(value: Any, name: str = "decisions") -> dict:
    """``TopoMap.decisions()`` data: loops (frames, status), manual (frames, yaw),
    labels (frame, label). Frames must be integers >= 0; whether they fall inside the
    recording is the map's business (``TopoMap.apply_decisions`` keeps the ones outside
    as unapplied rather than snapping them to the nearest node)."""
    dec = _mapping(value, name)
    out: dict = {}
    for key in ("loops", "manual", "labels"):
        if key not in dec:
            continue
        items = []
        for i, item in enumerate(_list(dec[key], f"{name}.{key}")):
            where = f"{name}.{key}[{i}]"
            item = _mapping(item, where)
            if key == "labels":
                label = item.get("label")
                if not isinstance(label, str) or len(label) > 1000:
                    raise _fail(f"{where}.label", "a text of at most 1000 characters", label)
                items.append({"frame": _frame(item.get("frame"), f"{where}.frame"), "label": label})
                continue
            clean = dict(item)
            clean["frames"] = _frames(item.get("frames"), f"{where}.frames")
            if key == "loops":
                if item.get("status") not in STATUSES:
                    raise _fail(f"{where}.status", f"one of {', '.join(STATUSES)}", item.get("status"))
            else:
                clean["yaw"] = _optional_number(item.get("yaw"), f"{where}.yaw")
            items.append(clean)
        out[key] = items
    return out


def check_describe(value: Any) -> dict:
    """Describe settings: descriptor name, interval, topic, shift flag, allow-listed options."""
    d = _mapping(value, "describe")
    out: dict = {}
    if "descriptor" in d:
        if not isinstance(d["descriptor"], str) or not d["descriptor"]:
            raise _fail("describe.descriptor", "a descriptor name", d["descriptor"])
        out["descriptor"] = d["descriptor"]
    if "interval" in d:
        out["interval"] = validate.interval(d["interval"], "session field 'describe.interval'")
    if "topic" in d:
        if d["topic"] is not None and not isinstance(d["topic"], str):
            raise _fail("describe.topic", "a topic name or null", d["topic"])
        out["topic"] = d["topic"]
    for flag in ("shift", "skip_bad_frames"):
        if flag in d:
            if not isinstance(d[flag], bool):
                raise _fail(f"describe.{flag}", "true or false", d[flag])
            out[flag] = d[flag]
    if "options" in d:
        from .descriptors import DEFAULT_DESCRIPTOR

        out["options"] = validate.describe_options(
            out.get("descriptor", DEFAULT_DESCRIPTOR), _mapping(d["options"], "describe.options"),
            name=lambda key: f"session field 'describe.options.{key}'".replace(".'", "'"),
            from_file=True)
    return out


def check_params(value: Any) -> dict:
    """Map parameters: known keys only, each of its type and range."""
    from dataclasses import fields

    from .params import MapParams

    p = _mapping(value, "params")
    known = {f.name for f in fields(MapParams)}
    out = {k: v for k, v in p.items() if k in known}
    if "long_runs" in out and not isinstance(out["long_runs"], bool):
        raise _fail("params.long_runs", "true or false", out["long_runs"])
    if "method" in out and not isinstance(out["method"], str):
        raise _fail("params.method", "a method name", out["method"])
    for key in ("window_size", "count_th", "neighbor_node_num"):
        if key in out and (isinstance(out[key], bool) or not isinstance(out[key], int)):
            raise _fail(f"params.{key}", "an integer", out[key])
    for key in ("node_sim_th", "loop_sim_th"):
        if key in out and out[key] is not None and (isinstance(out[key], bool) or not isinstance(out[key], (int, float))):
            raise _fail(f"params.{key}", "a number or null", out[key])
    validate.map_params(MapParams(**out), name=lambda key: f"session field 'params.{key}'")
    return out


def check_view(value: Any) -> dict:
    """View state: frame (int >= 0), tab and filter (int >= 0), selected (two frames)."""
    v = _mapping(value, "view")
    out = dict(v)
    for key in ("frame", "tab", "filter"):
        if key in v and v[key] is not None:
            out[key] = _frame(v[key], f"view.{key}")
    if "selected" in v and v["selected"] is not None:
        out["selected"] = _frames(v["selected"], "view.selected")
    return out


def check_session(data: dict, newest_version: int) -> dict:
    """The checked fields of a session's JSON object (format already checked)."""
    version = check_version(data.get("version"), newest_version)
    source = data.get("input")
    if not isinstance(source, str) or not source:
        raise InputError("session has no input recording (field 'input')")
    poses = data.get("poses")
    if poses is not None:
        if not isinstance(poses, dict) or not isinstance(poses.get("path"), str) or not poses["path"]:
            raise _fail("poses", "a mapping with a 'path'", poses)
        if poses.get("topic") is not None and not isinstance(poses["topic"], str):
            raise _fail("poses.topic", "a topic name or null", poses["topic"])
    return {
        "version": version,
        "input": source,
        "describe": check_describe(data.get("describe")),
        "params": check_params(data.get("params")),
        "decisions": check_decisions(data.get("decisions")),
        "poses": poses,
        "view": check_view(data.get("view")),
    }
