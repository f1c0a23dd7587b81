"""A site (several recordings) in the Qt-free application model (gui/model: site, queue, journal).

The site is three small recordings made here in a second: A and B see the same places
(B drives A's route backwards), C another world. Each recording is a folder of frames
whose pixels say which recording and which frame they are (``frame_code``), and its
descriptors .npz names that folder as its ``source``, as ``panotopo describe`` does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.params import MapParams

NAMES = ("A", "B", "C")
FRAMES = 30
WIDTH, HEIGHT = 128, 64


def frame_code(recording: int, frame: int) -> tuple[int, int]:
    """The red and green values every pixel of frame ``frame`` of recording ``recording`` has."""
    return 40 + 60 * recording, (7 * frame) % 256


def make_site_files(root: Path, n: int = FRAMES, seed: int = 0) -> dict:
    """Three recordings (folders of frames) and their descriptors: {"A": npz, ..., "A_frames": folder}."""
    from PIL import Image

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)

    def places(m: int) -> np.ndarray:   # a place each, a little like the one before
        r = rng.normal(size=(m + 1, 64))
        return r[1:] + 0.5 * r[:-1]

    route = places(n - 5)
    route = np.concatenate([route, route[:5]])          # A comes back to where it started
    worlds = {"A": route, "B": route[::-1].copy(), "C": places(n)}
    out = {}
    for k, name in enumerate(NAMES):
        folder = root / f"{name}_frames"
        folder.mkdir(exist_ok=True)
        texture = rng.integers(0, 256, size=(HEIGHT, WIDTH), dtype=np.uint8)
        for f in range(n):
            img = np.empty((HEIGHT, WIDTH, 3), np.uint8)
            img[..., 0], img[..., 1] = frame_code(k, f)
            img[..., 2] = np.roll(texture, 3 * f, axis=1)
            Image.fromarray(img).save(folder / f"frame_{f:04d}.png")
        base = worlds[name]
        vectors = base + 0.7 / 8.0 * np.linalg.norm(base, axis=1, keepdims=True) * rng.normal(size=base.shape)
        vectors /= np.linalg.norm(vectors, axis=1, keepdims=True)
        npz = root / f"{name}.npz"
        Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.int64),
                    shifts=np.zeros(n, np.int64), vectors=vectors.astype(np.float32),
                    meta={"descriptor": "effnet-vlad", "interval": 1.0, "shift": True, "source": str(folder)}).save(npz)
        out[name], out[f"{name}_frames"] = str(npz), str(folder)
    return out


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return make_site_files(tmp_path_factory.mktemp("site_model"))


def _site_doc(files, paths=None):
    """A MapDocument of the three recordings mapped as one site (no Qt)."""
    from engine.site import map_site
    from engine.sources import open_recording
    from gui.model.document import MapDocument
    from gui.model.site import open_site, plan_site

    plan = plan_site(paths or [files[n] for n in NAMES])
    site, frames, missing = open_site(plan, lambda p: open_recording(Path(p)))
    result = map_site(plan.inputs, MapParams(method="verified"))
    site.row_starts = list(result.row_starts)
    doc = MapDocument()
    doc.site = site
    doc.set_source(site.anchor, frames)
    doc.replace_map(result.topomap, result.descs)
    return doc, missing


def test_a_site_plan_names_each_recording_and_a_site_file_beside_them(files):
    from gui.model.site import plan_site

    plan = plan_site([files[n] for n in NAMES])
    assert [s.name for s in plan.sessions] == ["A.npz", "B.npz", "C.npz"]
    assert plan.new and plan.anchor.name == "A+B+C.site.graphml" and plan.anchor.parent == Path(files["A"]).parent
    with pytest.raises(InputError, match="no such file"):
        plan_site([files["A"], str(Path(files["A"]).with_name("gone.npz"))])


def test_site_frames_are_each_recordings_own_frames_on_one_timeline(files):
    doc, missing = _site_doc(files)
    site = doc.site
    assert missing == ""
    assert [r.span for r in site.recordings] == [FRAMES] * 3
    for name in site.names:   # every node's site frame goes back to its recording and frame
        nodes = [(n, d) for n, d in doc.topomap.graph.nodes(data=True) if d["session"] == name]
        assert nodes
        for node, d in nodes:
            place = doc.node_place(int(d["index"]))
            assert site.local(place) == (name, int(d["frame"]))
            assert doc.node_of_frame(place) == node
    # the frame source reads a site frame from its own recording, by its own frame number
    k = site.names.index("B.npz")
    frame = doc.source.frame_at(site.place("B.npz", 7))
    assert tuple(frame.rgb[0, 0, :2]) == frame_code(k, 7)


def test_the_queue_filters_by_pair_of_recordings(files):
    from gui.model.queue import ReviewQueue

    doc, _ = _site_doc(files)
    queue = ReviewQueue(doc)
    rows = queue.rows()
    assert rows and all(r.sessions is not None for r in rows)
    choices = queue.pair_choices()
    assert choices[0][1] is None and choices[0][2] == len(rows)
    assert {c[1] for c in choices[1:]} == {("A.npz", "A.npz"), ("A.npz", "B.npz"), ("A.npz", "C.npz"),
                                           ("B.npz", "B.npz"), ("B.npz", "C.npz"), ("C.npz", "C.npz")}
    assert sum(c[2] for c in choices[1:]) == len(rows)       # every loop in exactly one pair
    for _text, pair, count, undecided in choices[1:]:
        shown = queue.rows(pair=pair)
        assert len(shown) == count and sum(r.undecided for r in shown) == undecided
        assert all(set(r.sessions) == set(pair) for r in shown)
        assert queue.rows(pair=(pair[1], pair[0])) == shown      # either way round
    across = queue.rows(pair=("A.npz", "B.npz"))
    assert across, "B drives A's route back: loops join them"
    assert not queue.rows(pair=("A.npz", "C.npz")), "C is another world"
    assert queue.rows(statuses=("candidate",), pair=("A.npz", "B.npz")) == [
        r for r in across if r.status == "candidate"]


def test_decisions_on_a_site_name_each_recording_and_replay(files):
    from gui.model import journal
    from gui.model.commands import SetStatuses, SetLabel

    class Book:   # a journal: what the document writes through
        def __init__(self):
            self.records = []

        def append(self, record):
            self.records.append(record)

    doc, _ = _site_doc(files)
    doc.journal = book = Book()
    row = next(r for r in doc.loop_rows() if r.sessions == ("A.npz", "B.npz"))
    doc.push(SetStatuses({row.key: row.status}, {row.key: "confirmed"}))
    place = doc.node_place(row.index_v)
    doc.push(SetLabel(place, "", "stairs"))
    status, label = book.records
    for r in doc.loop_rows():   # after an edit, as before: every key names its rows' recordings
        assert sorted(doc.site.local(f)[0] for f in r.key) == sorted(r.sessions)
    assert sorted(status["sessions"]) == ["A.npz", "B.npz"] and status["status"] == "confirmed"
    assert label["session"] == "B.npz" and doc.site.local(place) == ("B.npz", label["frame"])
    assert all(f < FRAMES for f in status["frames"])              # each recording's own frame, never a site frame
    decisions, skipped = journal.replay_checked(book.records)
    assert skipped == 0
    # replayed on a new map of the same site: the same loop confirmed, the same node named
    again, _ = _site_doc(files)
    again.replace_map(again.topomap, decisions=decisions)
    assert {r.key: r.status for r in again.loop_rows()}[row.key] == "confirmed"
    assert again.label_of_frame(place) == "stairs"
    # a damaged record naming no recording's name is skipped, never applied
    bad = dict(status, sessions=["A.npz", 3])
    assert journal.replay_checked([bad])[1] == 1


def test_a_site_whose_recording_is_gone_is_one_line(files, tmp_path):
    from gui.model.site import plan_site

    copied = make_site_files(tmp_path / "moved", n=12)
    from engine.site import map_site

    site_file = tmp_path / "moved" / "site.graphml"
    map_site([copied[n] for n in NAMES], MapParams(method="verified")).topomap.write_graphml(site_file)
    Path(copied["B"]).rename(tmp_path / "elsewhere.npz")
    with pytest.raises(InputError) as err:
        plan_site([str(site_file)])
    assert "B.npz" in str(err.value) and "\n" not in str(err.value)
