"""The shipped resources: icon files, the freedesktop entry, the default settings, package data."""

from __future__ import annotations

import configparser
import dataclasses
import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

import resources
from engine.descriptors import names as descriptor_names
from engine.params import METHODS, MapParams

ROOT = Path(__file__).resolve().parent.parent


def read_desktop_entry(path: Path) -> configparser.SectionProxy:
    parser = configparser.ConfigParser(interpolation=None)  # Exec has %f, not an interpolation
    parser.optionxform = str  # keys are case-sensitive in desktop entries
    parser.read(path, encoding="utf-8")
    return parser["Desktop Entry"]


@pytest.mark.parametrize("size", resources.ICON_SIZES)
def test_png_icon_has_its_size_and_a_transparent_rounded_tile(size: int) -> None:
    path = resources.icon_path(size)
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, f"{path} is not a readable image"
    assert image.shape == (size, size, 4)
    alpha = image[..., 3]
    assert alpha[0, 0] == 0 and alpha[-1, -1] == 0  # rounded corners are see-through
    assert alpha[size // 2, size // 2] == 255
    assert image[..., :3].std() > 20  # a picture, not a flat fill


def test_unknown_icon_size_is_refused() -> None:
    with pytest.raises(ValueError, match="sizes"):
        resources.icon_path(17)


def test_svg_icon_is_valid_and_square(qapp) -> None:
    from PySide6.QtSvg import QSvgRenderer

    renderer = QSvgRenderer(str(resources.icon_path()))
    assert renderer.isValid()
    assert renderer.defaultSize().width() == renderer.defaultSize().height() == 256


def test_window_icon_png_is_the_256_icon() -> None:
    big = cv2.imread(str(resources.RESOURCES_DIR / "panotopo.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(big, cv2.imread(str(resources.icon_path(256)), cv2.IMREAD_UNCHANGED))


def test_desktop_entry_has_the_required_keys() -> None:
    entry = read_desktop_entry(resources.desktop_entry_path())
    for key in ("Name", "Exec", "Icon", "Type", "Categories"):
        assert entry.get(key), f"desktop entry has no {key}"
    assert entry["Type"] == "Application"
    assert entry["Exec"].split()[:2] == ["panotopo", "gui"]
    assert entry["Icon"] == resources.DESKTOP_FILE_NAME == resources.desktop_entry_path().stem
    assert entry["Categories"].endswith(";")
    assert entry["StartupWMClass"] == resources.DESKTOP_FILE_NAME


def test_default_settings_are_valid_engine_parameters() -> None:
    settings = resources.default_settings()
    fields = {f.name for f in dataclasses.fields(MapParams)}
    assert set(settings["map"]) <= fields, f"unknown map parameters: {set(settings['map']) - fields}"
    params = MapParams(**settings["map"])
    assert params.method in METHODS
    assert params == MapParams()  # the shipped defaults are the engine's defaults
    assert settings["describe"]["descriptor"] in descriptor_names()
    assert settings["describe"]["interval"] > 0
    assert settings["eval"]["dist_th"] > 0
    ui = settings["ui"]
    assert ui["window_width"] > 0 and ui["window_height"] > 0 and ui["autosave_seconds"] > 0


def test_default_settings_is_a_fresh_copy() -> None:
    first = resources.default_settings()
    first["map"]["window_size"] = -1
    assert resources.default_settings()["map"]["window_size"] != -1


def test_wheel_ships_the_resources_and_the_installed_package_finds_them(tmp_path: Path) -> None:
    # Build a wheel of the project (resources only, to stay fast), unpack it as an install would
    # and ask the installed package for its files (-S: no site-packages, so not the source checkout).
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "resources", src / "resources", ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation", "--no-index",
         "-q", "-w", str(tmp_path / "wheel")],
        check=True, capture_output=True, timeout=180,
    )
    (wheel,) = (tmp_path / "wheel").glob("panotopo-*.whl")
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    script = (
        "import json, resources\n"
        "paths = [resources.icon_path(), resources.desktop_entry_path(), resources.default_settings_path(),"
        " resources.RESOURCES_DIR / 'panotopo.png', *resources.icon_paths()]\n"
        "print(json.dumps({'dir': str(resources.RESOURCES_DIR), 'missing': [str(p) for p in paths if not p.is_file()],"
        " 'map': resources.default_settings()['map']}))\n"
    )
    out = subprocess.run([sys.executable, "-S", "-c", script], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(site)}, check=True, timeout=60)
    found = json.loads(out.stdout)
    assert Path(found["dir"]) == site / "resources"
    assert found["missing"] == []
    assert found["map"] == resources.default_settings()["map"]


def test_bundle_entry_script_runs_the_console_script() -> None:
    # The PyInstaller entry must call the same function as the installed `panotopo` command.
    import ast
    import tomllib

    script = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]["panotopo"]
    module, func = script.split(":")
    tree = ast.parse((ROOT / "packaging" / "panotopo_entry.py").read_text())
    imported = {(node.module, alias.name) for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                for alias in node.names}
    assert (module, func) in imported, f"packaging/panotopo_entry.py does not import {script}"
