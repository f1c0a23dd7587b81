"""The layer rules: engine never imports Qt or gui, gui.model never imports Qt (each checked two
ways), and the engine's layers (commands, pipeline, loop detection, its stages) have no cycles."""

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

def blocked_import_probe(package: str, blocked: tuple[str, ...], skip_suffix: str = "__main__") -> str:
    """A script that imports every module of ``package`` with ``blocked`` top-level packages
    made unimportable, and prints how many modules it imported."""
    return textwrap.dedent(
        f"""
        import importlib, pkgutil, sys
        BLOCKED = {blocked!r}

        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in BLOCKED:
                    raise ImportError(f"{package} imported {{name}}")
                return None

        sys.meta_path.insert(0, Block())
        import {package} as root
        names = [m.name for m in pkgutil.walk_packages(root.__path__, "{package}.")
                 if not m.name.endswith("{skip_suffix}")]  # running a CLI is not importing it
        for name in names:
            importlib.import_module(name)
        print(len(names))
        """
    )


BLOCKED_IMPORT_PROBE = blocked_import_probe("engine", ("PySide6", "shiboken6", "pyqtgraph", "gui"))


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
    assert " 0 broken" in out.stdout
    for contract in ("engine layers", "loop detection: the pipeline over its stages", "sources are a leaf",
                     "no frames <-> sources circle"):
        assert contract in out.stdout        # each contract is checked, not only present in the file


MODEL_PROBE = blocked_import_probe("gui.model", ("PySide6", "shiboken6", "pyqtgraph", "superqt"))


def test_every_app_model_module_imports_with_qt_hidden():
    out = subprocess.run([sys.executable, "-c", MODEL_PROBE], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.strip().splitlines()[-1]) >= 5  # the walk really found the modules
