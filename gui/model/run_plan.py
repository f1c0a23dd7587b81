"""What a change asks for, decided in plain Python: describe again, re-map, or nothing.

The window asks this module and carries out the answer; nothing here runs anything.
"""

from __future__ import annotations

from typing import Optional

from engine.params import MapParams

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
