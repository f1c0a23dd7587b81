"""Data shipped with panotopo: the application icon, the freedesktop entry, the default settings.

Plain paths and plain data (no Qt here), found next to this file both in a source checkout,
in an installed wheel and in the PyInstaller bundle (where they sit in ``_internal/resources``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

RESOURCES_DIR = Path(__file__).resolve().parent
DESKTOP_FILE_NAME = "panotopo"  # for QGuiApplication.setDesktopFileName: matches panotopo.desktop
ICON_SIZES = (16, 32, 48, 64, 128, 256)


def icon_path(size: Optional[int] = None) -> Path:
    """The application icon: the SVG without ``size``, else the PNG of that many pixels."""
    if size is None:
        return RESOURCES_DIR / "panotopo.svg"
    if size not in ICON_SIZES:
        raise ValueError(f"no {size} px icon; sizes: {', '.join(map(str, ICON_SIZES))}")
    return RESOURCES_DIR / "icons" / f"{size}x{size}" / "panotopo.png"


def icon_paths() -> list[Path]:
    """Every PNG size of the icon, smallest first (add them all to one QIcon)."""
    return [icon_path(size) for size in ICON_SIZES]


def desktop_entry_path() -> Path:
    """The freedesktop ``.desktop`` entry (install it as ~/.local/share/applications/panotopo.desktop)."""
    return RESOURCES_DIR / f"{DESKTOP_FILE_NAME}.desktop"


def default_settings_path() -> Path:
    return RESOURCES_DIR / "default_settings.json"


def default_settings() -> dict:
    """The app's default settings: ``map`` (engine.params.MapParams fields), ``describe``, ``eval``, ``ui``.

    A fresh dict on every call, so callers may change it.
    """
    with open(default_settings_path(), encoding="utf-8") as f:
        return json.load(f)
