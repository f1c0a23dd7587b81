"""The PySide6 emit bug workaround: many emits must not abort the process."""

import os
import subprocess
import sys
from pathlib import Path

SCRIPT = """
import gui  # applies the workaround when this PySide6 needs it
from PySide6.QtCore import QObject, Signal

class Source(QObject):
    changed = Signal(int)

s = Source()
seen = []
s.changed.connect(seen.append)
for i in range(20000):  # far more than True's initial reference count
    s.changed.emit(i)
assert len(seen) == 20000
print("ok")
"""


def test_many_emits_do_not_abort():
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=root, env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "ok"
