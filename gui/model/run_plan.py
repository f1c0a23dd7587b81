"""What a change asks for, decided in plain Python: describe again, re-map, or nothing.

The window asks this module and carries out the answer; nothing here runs anything.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from engine.params import MapParams

# What a parameter change asks for.
REMAP = "remap"          # the descriptors fit: build the map again from them
DESCRIBE = "describe"    # the method needs other descriptors: describe the recording again
REFUSE = "refuse"        # a descriptors file cannot give what the method needs (``message`` says why)
WAIT = "wait"            # no descriptors yet, or a run's map on its way: it is built with these


@dataclass(frozen=True)
class Plan:
    action: str
    message: str = ""


def plan_change(new: MapParams, descs, describe_settings, descriptors_file: bool, run_landing: bool) -> Plan:
    """What a change to ``new`` asks for: describe again or re-map (issue 41, item 6).

    ``descs``: the descriptors shown now (None: none yet); ``describe_settings``: the
    user's own (``DescribeSettings``); ``descriptors_file``: a ``.npz`` was opened (it is
    what it is: it cannot be described again); ``run_landing``: a run's map is being
    prepared, and will be built with ``new`` when it lands.
    """
    from engine.pipeline import DescribeSettings, descriptors_fit, method_settings

    if descs is None or run_landing:
        return Plan(WAIT)
    # What the descriptors were described with (their meta) against what ``new`` asks for
    # on top of the user's own describe settings (panorama shift, a method's describe options).
    wanted = method_settings(new, describe_settings or DescribeSettings())
    if descriptors_fit(descs, wanted):
        return Plan(REMAP)
    if not descriptors_file:
        return Plan(DESCRIBE)   # cached when done before
    if new.uses_shift != bool(descs.meta.get("shift", True)):
        return Plan(REFUSE, f"Method '{new.method}' needs {'shifted' if new.uses_shift else 'unshifted'} "
                            "descriptors, which this descriptors file does not have")
    return Plan(REMAP)          # only a describe option differs: a descriptors file is mapped as it is

# Methods that calibrate an unset node threshold from the recording itself: before
# their map is built, the value it will use is not known.
CALIBRATING = ("verified", "verified-rules")
THRESHOLDS = ("node_sim_th", "loop_sim_th")


def known_thresholds(params: MapParams, map_meta: Optional[dict], descriptor_defaults: dict) -> dict:
    """The values unset thresholds stand for, where they are known (issue 43, defect 6).

    The map says what it was built with (``map_meta``, when it was built by ``params``'s
    method); otherwise the descriptor's defaults, except for a method that calibrates
    its own. A threshold missing from the answer is shown as "auto", never as a number
    that the next map will contradict.
    """
    known: dict = {}
    if map_meta is not None and map_meta.get("method") == params.method:
        for name in THRESHOLDS:
            if isinstance(map_meta.get(name), (int, float)):
                known[name] = float(map_meta[name])
        return {**{k: v for k, v in descriptor_defaults.items() if k not in THRESHOLDS}, **known} \
            if params.method in CALIBRATING else {**descriptor_defaults, **known}
    if params.method in CALIBRATING:
        return {k: v for k, v in descriptor_defaults.items() if k not in THRESHOLDS}
    return dict(descriptor_defaults)


def needs_remap(built_with: MapParams, wanted: MapParams) -> bool:
    """A run finished with parameters the user has changed meanwhile: build the map again?

    Only the map step needs repeating when the descriptors still fit (the same describe
    needs: panorama shift and the method's describe options, ``MapParams.describe_needs``);
    a method that needs other descriptors starts a new describe run instead.
    """
    return built_with != wanted and built_with.describe_needs == wanted.describe_needs
