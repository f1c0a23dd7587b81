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
LABEL_MAX = 1000   # characters of a place name (the app's field enforces it where it is typed)


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


SESSION_NAME_MAX = 4096   # characters of a recording's name in a site's decisions


def _session_name(value: Any, name: str) -> str:
    if not isinstance(value, str) or not value or len(value) > SESSION_NAME_MAX:
        raise _fail(name, "a recording's name", value)
    return value


def check_decisions(value: Any, name: str = "decisions") -> dict:
    """``TopoMap.decisions()`` data: loops (frames, status), manual (frames, yaw),
    labels (frame, label); a site's items also name their recordings (loops ``sessions``,
    two names; labels ``session``). Frames must be integers >= 0; whether they fall inside the
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
                if not isinstance(label, str) or len(label) > LABEL_MAX:
                    raise _fail(f"{where}.label", f"a text of at most {LABEL_MAX} characters", label)
                clean = {"frame": _frame(item.get("frame"), f"{where}.frame"), "label": label}
                if item.get("session") is not None:
                    clean["session"] = _session_name(item["session"], f"{where}.session")
                items.append(clean)
                continue
            clean = dict(item)
            clean["frames"] = _frames(item.get("frames"), f"{where}.frames")
            if item.get("sessions") is not None:
                names = item["sessions"]
                if not isinstance(names, list) or len(names) != 2:
                    raise _fail(f"{where}.sessions", "two recording names", names)
                clean["sessions"] = [_session_name(n, f"{where}.sessions") for n in names]
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
    if d.get("projection") is not None:   # the --projection text; checked as the option is
        from .sources.projection import parse_projection

        if not isinstance(d["projection"], str):
            raise _fail("describe.projection", "a projection such as dual-fisheye:fov=200, or null", d["projection"])
        parse_projection(d["projection"])
        out["projection"] = d["projection"]
    if "sampling" in d:
        if d["sampling"] not in ("interval", "keyframes"):
            raise _fail("describe.sampling", "'interval' or 'keyframes'", d["sampling"])
        out["sampling"] = d["sampling"]
    for flag in ("shift", "skip_bad_frames"):
        if flag in d:
            if not isinstance(d[flag], bool):
                raise _fail(f"describe.{flag}", "true or false", d[flag])
            out[flag] = d[flag]
    if "options" in d:
        from .descriptors import DEFAULT_DESCRIPTOR

        out["options"] = file_options(out.get("descriptor", DEFAULT_DESCRIPTOR),
                                      _mapping(d["options"], "describe.options"))
    return out


# Options dropped from any file, for any descriptor: a download is the user's choice,
# made again each time, never a file's. (Options that would run or write something are
# in no allow-list, so a file naming one is refused.)
NEVER_FROM_FILE = ("allow_download",)
# What a file may set for a descriptor the allow-list (``engine.validate.ALLOWED_OPTIONS``)
# has no table for (megaloc, boq: networks fixed by their weights): sizes, the device, the
# precision and a weights file to READ (``torch.load(weights_only=True)``).
_PRECISIONS = ("auto", "fp32", "fp16", "bf16")


def _safe_generic(key: str, value: Any, name: str):
    if key == "input_height":
        from . import limits

        return validate.integer(value, name, lo=limits.MIN_INPUT_HEIGHT, hi=limits.MAX_INPUT_HEIGHT)
    if key == "batch_size":
        from . import limits

        return validate.integer(value, name, lo=1, hi=limits.MAX_BATCH_SIZE)
    if key == "device":
        if not isinstance(value, str) or value.strip().lower().partition(":")[0] not in ("auto", "cpu", "cuda", "mps"):
            raise InputError(f"{name}: expected auto, cpu, cuda, cuda:N or mps, got {value!r}")
        return value
    if key == "precision":
        if value not in _PRECISIONS:
            raise InputError(f"{name}: expected one of {', '.join(_PRECISIONS)}, got {value!r}")
        return value
    if key == "weights":
        return validate.readable_file(value, name)
    raise InputError(f"{name}: not an option a session file may set "
                     f"(allowed: batch_size, device, input_height, precision, weights)")


def file_options(descriptor: str, options: dict) -> dict:
    """The describe options of a session (or any file) for ``descriptor``, checked.

    Whatever the descriptor, no option read from a file may download, execute or write
    elsewhere: ``NEVER_FROM_FILE`` keys are dropped before anything else looks at them
    (the allow-list of ``engine.validate`` returns early for descriptors it has no table
    for, so the filter must not depend on it), and a descriptor with no table gets the
    short safe list of ``_safe_generic``. Options for an unknown descriptor are refused."""
    from .descriptors import REGISTRY

    def name(key: str) -> str:
        return f"session field 'describe.options.{key}'"

    clean = {k: v for k, v in options.items() if k not in NEVER_FROM_FILE}
    if descriptor not in REGISTRY:  # options nobody can check (the name itself is refused when used)
        if clean:
            raise _fail("describe.descriptor", f"one of {', '.join(sorted(REGISTRY))}", descriptor)
        return {}
    if descriptor in validate.ALLOWED_OPTIONS:
        return validate.describe_options(descriptor, clean, name=lambda key: name(key).replace(".'", "'"),
                                         from_file=True)
    return {k: _safe_generic(k, v, name(k)) for k, v in clean.items() if v is not None}


def check_params(value: Any) -> dict:
    """Map parameters: known keys only, each of its type and range."""
    from dataclasses import fields

    from .params import MapParams

    from .params import RETIRED_METHODS

    p = _mapping(value, "params")
    known = {f.name for f in fields(MapParams)}
    out = {k: v for k, v in p.items() if k in known}   # a retired method's own parameters are left out
    if isinstance(out.get("method"), str) and out["method"] in RETIRED_METHODS:
        import warnings

        new = RETIRED_METHODS[out["method"]]
        warnings.warn(f"this session names the method '{out['method']}', which panotopo no longer ships; "
                      f"it opens with '{new}', which replaced it")
        out["method"] = new
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
