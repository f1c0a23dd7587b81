"""The app's settings and icon: resources/default_settings.json under the user's settings file.

The user's file (``user_settings_path``) has the same sections as the defaults, each
optional; a broken one is ignored with one line, so the window always opens.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from PySide6.QtGui import QIcon

APP_NAME = "panotopo"


def default_settings() -> dict:
    """resources/default_settings.json, or built-in values if it is missing or broken."""
    fallback = {"map": {}, "describe": {}, "eval": {}, "ui": {}, "shortcuts": {}}
    try:
        import resources

        data = resources.default_settings()
    except Exception:  # the window must open even with a damaged install
        data = {}
    out = {k: dict(data.get(k) or {}) for k in fallback}
    user = _user_settings()
    for section in fallback:
        if isinstance(user.get(section), dict):
            out[section].update(user[section])
    return out


def user_settings_path() -> Path:
    """The user's settings file: same sections as resources/default_settings.json, each optional."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / APP_NAME / "settings.json"


def _user_settings() -> dict:
    path = user_settings_path()
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:  # a broken file must not stop the app
        print(f"panotopo: {path}: ignored ({exc.__class__.__name__})", file=sys.stderr)
        return {}
    return data if isinstance(data, dict) else {}


def app_icon() -> QIcon:
    icon = QIcon()
    try:
        import resources

        for path in resources.icon_paths():
            if path.is_file():
                icon.addFile(str(path))
    except Exception:
        pass
    return icon

