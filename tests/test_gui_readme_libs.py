"""The README names every X11 library Qt's xcb platform plugin needs on Linux (issue 14, defect 12)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def _debian_package(soname: str) -> str:
    """Debian's name for the package of a shared library: ``libxcb-cursor.so.0`` -> ``libxcb-cursor0``."""
    name, version = re.match(r"(.+)\.so\.(\d+)", soname).groups()
    name = name.lower()
    return f"{name}-{version}" if name[-1].isdigit() else f"{name}{version}"


def test_readme_names_the_xcb_plugin_libraries():
    if not sys.platform.startswith("linux") or shutil.which("ldd") is None:
        pytest.skip("the xcb plugin is a Linux matter")
    import PySide6

    qt = Path(PySide6.__file__).parent / "Qt"
    files = [qt / "plugins" / "platforms" / "libqxcb.so", *sorted((qt / "lib").glob("libQt6XcbQpa.so*"))[:1]]
    files = [f for f in files if f.exists()]
    if not files:
        pytest.skip("this PySide6 has no xcb plugin")
    out = subprocess.run(["ldd", *map(str, files)], capture_output=True, text=True).stdout
    sonames = set(re.findall(r"^\s*((?:libxcb|libxkbcommon|libX11-xcb|libEGL)[\w.+-]*\.so\.\d+)", out, re.M))
    assert sonames, "ldd lists the plugin's X11 libraries"
    text = README.read_text(encoding="utf-8")
    missing = sorted(p for p in map(_debian_package, sonames) if p not in text)
    assert not missing, f"README does not name {missing}"
    assert 'Could not load the Qt platform plugin "xcb"' in text
