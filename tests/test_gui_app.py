"""``gui.app.run``: the entry behind ``panotopo gui INPUT --screenshot PNG``, in a real process."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(args: list, tmp_path: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", XDG_CONFIG_HOME=str(tmp_path / "config"),
               PANOTOPO_CACHE=str(tmp_path / "cache"))
    code = "import sys; from gui.app import run; sys.exit(run(*sys.argv[1:3]))"
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def descriptors_file(tmp_path_factory):
    """A descriptors .npz of a small synthetic recording (the video stays beside it for the viewer)."""
    from engine.pipeline import DescribeSettings, describe
    from engine.synth import make_recording, write_recording

    out = tmp_path_factory.mktemp("app")
    rec = make_recording(route="loop", look="indoor", width=256, height=128, fps=2.0, max_frames=160)
    paths = write_recording(rec, out, formats=("video", "poses"))
    descs = describe(paths["video"], DescribeSettings(options={"input_height": 64}))
    npz = out / "walk.npz"
    descs.save(npz)
    return npz


@pytest.fixture(scope="module")
def screenshot(descriptors_file, tmp_path_factory):
    """One screenshot run of the descriptors file (its own config and cache folders); the tests
    below read what it left, and change nothing."""
    tmp = tmp_path_factory.mktemp("shot")
    png = tmp / "window.png"
    proc = _run([descriptors_file, png], tmp)
    return proc, png, tmp / "config"


def test_screenshot_of_a_descriptors_file(screenshot):
    proc, png, _ = screenshot
    assert proc.returncode == 0, proc.stderr[-2000:]
    from PySide6.QtGui import QImage

    image = QImage(str(png))
    assert image.width() >= 1200 and image.height() >= 700
    # Not a blank window: many distinct colours (panoramas, the graph, the table).
    colours = {image.pixel(x, y) for x in range(0, image.width(), 7) for y in range(0, image.height(), 7)}
    assert len(colours) > 200


@pytest.mark.parametrize("name, content", [("broken.mp4", b"not a video"), ("nothing-here.mp4", None)])
def test_bad_input_exits_non_zero_with_one_line(tmp_path, name, content):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    png = tmp_path / "window.png"
    proc = _run([path, png], tmp_path)
    assert proc.returncode != 0
    lines = [line for line in proc.stderr.splitlines() if line.startswith("panotopo:")]
    assert len(lines) == 1 and name in lines[0]
    assert "Traceback" not in proc.stderr
    assert not png.exists()


def test_screenshot_leaves_the_recent_files_list_alone(screenshot, descriptors_file):
    """Finding 16 of issue 16: a screenshot run is not the user opening a file."""
    proc, _, config = screenshot
    assert proc.returncode == 0, proc.stderr[-2000:]
    written = "".join(p.read_text(errors="replace") for p in config.rglob("*") if p.is_file())
    assert "recent" not in written and str(descriptors_file) not in written
