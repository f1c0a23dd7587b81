"""The layer rules: engine never imports Qt or gui, gui.model never imports Qt (each checked two ways)."""

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

BLOCKED_IMPORT_PROBE = textwrap.dedent(
    """
    import importlib, pkgutil, sys
    BLOCKED = ("PySide6", "shiboken6", "pyqtgraph", "gui")

    class Block:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"engine imported {name}")
            return None

    sys.meta_path.insert(0, Block())
    import engine
    names = [m.name for m in pkgutil.walk_packages(engine.__path__, "engine.")
             if not m.name.endswith("__main__")]  # running the CLI is not importing it
    for name in names:
        importlib.import_module(name)
    print(len(names))
    """
)


def test_every_engine_module_imports_with_qt_hidden():
    out = subprocess.run([sys.executable, "-c", BLOCKED_IMPORT_PROBE], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.strip().splitlines()[-1]) >= 10  # the walk really found the modules


def test_import_linter_contract_holds():
    exe = shutil.which("lint-imports")
    assert exe, "import-linter is a test dependency; install the [test] extra"
    out = subprocess.run([exe, "--config", str(ROOT / "pyproject.toml")], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-1000:]
    assert "2 kept, 0 broken" in out.stdout


MODEL_PROBE = textwrap.dedent(
    """
    import importlib, pkgutil, sys
    BLOCKED = ("PySide6", "shiboken6", "pyqtgraph", "superqt")

    class Block:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"gui.model imported {name}")
            return None

    sys.meta_path.insert(0, Block())
    import gui.model
    names = [m.name for m in pkgutil.walk_packages(gui.model.__path__, "gui.model.")]
    for name in names:
        importlib.import_module(name)
    print(len(names))
    """
)


def test_every_app_model_module_imports_with_qt_hidden():
    out = subprocess.run([sys.executable, "-c", MODEL_PROBE], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.strip().splitlines()[-1]) >= 5  # the walk really found the modules
