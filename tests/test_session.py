import json
from pathlib import Path

import pytest

from engine.errors import InputError
from engine.params import MapParams
from engine.session import Session, autosave_path_for, session_path_for


def _session(tmp_path: Path) -> Session:
    rec = tmp_path / "walk.mp4"
    rec.write_bytes(b"")
    return Session(
        input_path=str(rec),
        describe={"descriptor": "x", "interval": 0.5, "topic": None, "shift": True, "options": {}},
        params=MapParams(method="shift-simple", loop_sim_th=0.6).as_dict(),
        decisions={"loops": [{"frames": [3, 40], "status": "confirmed"}]},
        poses_path=str(tmp_path / "poses.csv"),
        view={"frame": 12},
    )


def test_round_trip_keeps_everything(tmp_path):
    s = _session(tmp_path)
    path = session_path_for(s.input_path)
    assert path.name == "walk.mp4.panotopo.json"
    s.save(path)
    back = Session.load(path)
    assert back == s
    assert back.map_params() == MapParams(method="shift-simple", loop_sim_th=0.6)


def test_paths_are_relative_so_a_moved_folder_still_opens(tmp_path):
    s = _session(tmp_path)
    path = session_path_for(s.input_path)
    s.save(path)
    assert json.loads(path.read_text())["input"] == "walk.mp4"
    moved = tmp_path.parent / (tmp_path.name + "_moved")
    tmp_path.rename(moved)
    back = Session.load(moved / path.name)
    assert back.input_path == str((moved / "walk.mp4").resolve())
    assert back.poses_path == str((moved / "poses.csv").resolve())


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path):
    s = _session(tmp_path)
    path = tmp_path / "a.panotopo.json"
    s.save(path)
    s.decisions = {"loops": []}
    s.save(path)
    assert Session.load(path).decisions == {"loops": []}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.panotopo.json", "walk.mp4"]


def test_autosave_is_a_separate_file(tmp_path):
    assert autosave_path_for(tmp_path / "r.bag") != session_path_for(tmp_path / "r.bag")


@pytest.mark.parametrize("content, reason", [
    (b"\x00\xff garbage", "not valid JSON"),
    (b"{not json", "not valid JSON"),
    (b'{"format": "something-else"}', "not a panotopo session"),
    (b'[1, 2]', "not a panotopo session"),
    (b'{"format": "panotopo-session", "version": 1}', "no input"),
    (b'{"format": "panotopo-session", "version": 99, "input": "x"}', "newer"),
    (b'{"format": "panotopo-session", "version": 1, "input": "x", "decisions": [1]}', "'decisions'"),
    (b'{"format": "panotopo-session", "version": 1, "input": "x", "params": {"bogus": 1}}', None),
    (b'{"format": "panotopo-session", "version": 1, "input": "x", "params": {"window_size": "a"}}',
     "'params.window_size'"),
])
def test_bad_files_raise_input_error(tmp_path, content, reason):
    path = tmp_path / "bad.panotopo.json"
    path.write_bytes(content)
    if reason is None:  # unknown keys are ignored; a loadable file is fine
        Session.load(path)
        return
    with pytest.raises(InputError, match=reason):
        Session.load(path)


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no such session"):
        Session.load(tmp_path / "nope.json")
