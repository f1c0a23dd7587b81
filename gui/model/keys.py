"""The one table of keyboard shortcuts: menus, the help dialog and the README are built from it.

Each entry: an action id, the area it belongs to, its default keys (Qt's portable key
text, e.g. "Ctrl+Shift+Z") and what it does. The settings file overrides keys per
action id with a ``shortcuts`` mapping (labelme's ``shortcuts:`` is the model)::

    "shortcuts": {"confirm": ["C", "Y"], "next_undecided": "Tab", "reject": null}

(a string or a list of strings; null or [] removes the keys). Entries with
``fixed=True`` are handled by a widget itself (arrow keys in the frame viewer, a
Ctrl+click) and are listed for the help only: they cannot be overridden.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable, Mapping, Optional


@dataclass(frozen=True)
class Shortcut:
    action: str
    area: str
    keys: tuple[str, ...]
    text: str
    fixed: bool = False

    @property
    def shown(self) -> str:
        """The keys as the help and the README show them ("C or Y")."""
        return " or ".join(self.keys) if self.keys else "(none)"


def _s(action: str, area: str, keys: Iterable[str], text: str, fixed: bool = False) -> Shortcut:
    return Shortcut(action, area, tuple(keys), text, fixed)


SHORTCUTS: tuple[Shortcut, ...] = (
    _s("confirm", "Loops", ("C", "Y"), "Confirm the selected loops (same place)"),
    _s("reject", "Loops", ("R", "N"), "Reject the selected loops (different places)"),
    _s("reset", "Loops", ("Backspace", "U"), "Reset the selected loops to undecided"),
    _s("next_undecided", "Loops", ("F",), "Select the next undecided loop (candidate or auto)"),
    _s("next", "Loops", ("J", "PgDown"), "Next loop in the table (wraps to the first)"),
    _s("previous", "Loops", ("K", "PgUp"), "Previous loop in the table (wraps to the last)"),
    _s("reject_below", "Loops", ("Shift+R",), "Reject every undecided loop ranked below the selected one"),
    _s("select_all", "Loops", ("Ctrl+A",), "Select every loop shown (the filter applies)", fixed=True),
    _s("focus_queue", "Loops", ("Ctrl+L",), "Move the keyboard to the review queue (from any panel)"),
    _s("manual_loop", "Loops", ("M",), "Add a manual loop between two nodes"),
    _s("ctrl_click", "Loops", ("Ctrl+click",), "Manual loop from the current node to the clicked node (asks first)",
       fixed=True),
    _s("remove_manual", "Loops", ("Delete",), "Remove the selected manual loop"),
    _s("frame_step", "Frames", ("Left", "Right"), "Previous / next frame (frame viewer focused)", fixed=True),
    _s("node_step", "Frames", ("Shift+Left", "Shift+Right"), "Previous / next node (frame viewer focused)",
       fixed=True),
    _s("frame_ends", "Frames", ("Home", "End"), "First / last frame (frame viewer focused)", fixed=True),
    _s("play", "Frames", ("Space",), "Play / pause (frame viewer focused)", fixed=True),
    _s("name_place", "Frames", ("L",), "Name the place of the current node"),
    _s("undo", "Edit", ("Ctrl+Z",), "Undo (also in the place-name field once the name is applied)"),
    _s("redo", "Edit", ("Ctrl+Shift+Z", "Ctrl+Y"), "Redo"),
    _s("run", "Run", ("F5",), "Run the engine"),
    _s("cancel_run", "Run", ("Esc",), "Cancel the run"),
    _s("open", "File", ("Ctrl+O",), "Open a recording, bag, folder, session or descriptors"),
    _s("save", "File", ("Ctrl+S",), "Save the session"),
    _s("save_as", "File", ("Ctrl+Shift+S",), "Save the session under another name"),
    _s("export", "File", ("Ctrl+E",), "Export the corrected graph (GraphML)"),
    _s("quit", "File", ("Ctrl+Q",), "Quit"),
    _s("shortcuts", "Help", ("F1",), "Show this list of keys"),
)

_BY_ACTION = {s.action: s for s in SHORTCUTS}


def shortcut_table(overrides: Optional[Mapping[str, object]] = None) -> list[Shortcut]:
    """The table with the settings file's ``shortcuts`` mapping applied.

    Unknown action ids and fixed entries are ignored (a typo must not stop the app);
    ``bad_overrides`` names them for a warning.
    """
    table = list(SHORTCUTS)
    for action, value in (overrides or {}).items():
        entry = _BY_ACTION.get(action)
        keys = _keys(value)
        if entry is None or entry.fixed or keys is None:
            continue
        table[table.index(entry)] = replace(entry, keys=keys)
    return table


def bad_overrides(overrides: Optional[Mapping[str, object]]) -> list[str]:
    """Override entries that are ignored: unknown or fixed actions, values that are not keys."""
    bad = []
    for action, value in (overrides or {}).items():
        entry = _BY_ACTION.get(action)
        if entry is None or entry.fixed or _keys(value) is None:
            bad.append(str(action))
    return bad


def keys_for(action: str, table: Iterable[Shortcut] = SHORTCUTS) -> tuple[str, ...]:
    for entry in table:
        if entry.action == action:
            return entry.keys
    raise KeyError(f"no shortcut entry {action!r}")


def _keys(value) -> Optional[tuple[str, ...]]:
    if value is None:
        return ()
    if isinstance(value, str):
        return (value,) if value.strip() else ()
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) and v.strip() for v in value):
        return tuple(value)
    return None


README_START = "<!-- keys: generated from gui/model/keys.py; do not edit by hand -->"
README_END = "<!-- /keys -->"


def readme_section(table: Iterable[Shortcut] = SHORTCUTS) -> str:
    """The README's key list (between ``README_START`` and ``README_END``)."""
    lines = [README_START, "", "| Area | Keys | Action | Settings name |", "| --- | --- | --- | --- |"]
    for s in table:
        name = "(fixed)" if s.fixed else f"`{s.action}`"
        lines.append(f"| {s.area} | {' or '.join(f'`{k}`' for k in s.keys)} | {s.text} | {name} |")
    lines += ["", README_END]
    return "\n".join(lines)
