"""The decision journal: replay, torn lines, one key for recording/session/autosave, the lock
between instances, the fallback place for read-only folders (issue 16, findings 1-4)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from engine.journal import Journal, JournalLocked
from engine.session import autosave_path_for, session_path_for

ROOT = Path(__file__).resolve().parent.parent


def test_records_come_back_in_order_and_compact_empties(tmp_path):
    rec = tmp_path / "walk.mp4"
    with Journal.open(session_path_for(rec)) as j:
        for n in range(5):
            j.append({"n": n})
        assert [r["n"] for r in j.replay()] == list(range(5))
        j.compact()
        assert j.replay() == []
        j.append({"n": 9})
    with Journal.open(session_path_for(rec)) as j:
        assert j.replay() == [{"n": 9}]


def test_compact_keeps_what_came_after_the_save(tmp_path):
    with Journal.open(tmp_path / "walk.mp4") as j:
        j.append({"n": 1})
        saved_upto = j.last_seq
        j.append({"n": 2})          # made while the save was being written
        j.compact(upto=saved_upto)
        assert j.replay() == [{"n": 2}]
        j.append({"n": 3})
        assert j.replay() == [{"n": 2}, {"n": 3}]


def test_recording_session_and_autosave_find_the_same_journal(tmp_path):
    """Finding 2: reopening the .panotopo.json (not the recording) offered nothing back."""
    rec = tmp_path / "demo.mp4"
    with Journal.open(rec) as j:
        j.append({"decision": 1})
    for way in (rec, session_path_for(rec), autosave_path_for(rec)):
        with Journal.open(way) as j:
            assert j.replay() == [{"decision": 1}], way


def test_a_torn_last_line_is_ignored_and_cut_before_the_next_record(tmp_path):
    session = session_path_for(tmp_path / "walk.mp4")
    with Journal.open(session) as j:
        j.append({"n": 1})
        j.append({"n": 2})
        path = j.path
    with open(path, "ab") as f:
        f.write(b'{"seq": 3, "time": 1.0, "data": {"n"')   # died mid-write
    with Journal.open(session) as j:
        assert j.replay() == [{"n": 1}, {"n": 2}]
        j.append({"n": 3})
    with Journal.open(session) as j:
        assert j.replay() == [{"n": 1}, {"n": 2}, {"n": 3}]
        assert j.damaged == 0


def test_a_second_instance_is_told_who_holds_the_journal(tmp_path):
    """Finding 3: two instances on one recording, the last writer won silently."""
    session = session_path_for(tmp_path / "walk.mp4")
    code = ("import sys, time; from engine.journal import Journal; j = Journal.open(sys.argv[1]); "
            "j.append({'n': 1}); print('locked', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", code, str(session)], cwd=ROOT, stdout=subprocess.PIPE,
                              text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(JournalLocked) as err:
            Journal.open(session)
        assert f"pid {holder.pid}" in str(err.value)
        ro = Journal.open(session, read_only=True)     # the app may still show the work
        assert ro.replay() == [{"n": 1}]
        with pytest.raises(Exception):
            ro.append({"n": 2})
    finally:
        holder.kill()
        holder.wait()
    with Journal.open(session) as j:                    # a killed holder leaves no stale lock
        assert j.replay() == [{"n": 1}]


def _folder_we_cannot_write(tmp_path: Path) -> Path:
    """A folder this process cannot create files in: a 0555 folder, or for root (who may
    write anywhere on a normal file system) a folder of /proc, which nobody can add to."""
    if os.geteuid() != 0:
        ro = tmp_path / "readonly"
        ro.mkdir()
        os.chmod(ro, 0o555)
        return ro
    ro = Path("/proc/self/fdinfo")
    if not ro.is_dir():
        pytest.skip("no folder that root cannot write")
    return ro


def test_a_read_only_folder_falls_back_to_the_state_folder(tmp_path):
    """Finding 4: autosave failed in a read-only folder and had nowhere else to go."""
    ro = _folder_we_cannot_write(tmp_path)
    state = tmp_path / "state"
    try:
        with Journal.open(ro / "walk.mp4", fallback_dir=state) as j:
            j.append({"n": 1})
            assert j.fallback is True and j.path.parent == state
        with Journal.open(ro / "walk.mp4", fallback_dir=state) as j:
            assert j.replay() == [{"n": 1}]
        assert not any(p.name.startswith("walk.mp4") for p in ro.iterdir())
    finally:
        if ro.is_relative_to(tmp_path):
            os.chmod(ro, 0o755)


def test_the_default_fallback_place_is_the_xdg_state_folder(tmp_path, monkeypatch):
    from engine.journal import state_dir

    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert state_dir() == tmp_path / "xdg" / "panotopo" / "journals"
    monkeypatch.delenv("XDG_STATE_HOME")
    assert state_dir() == Path.home() / ".local" / "state" / "panotopo" / "journals"


def test_opening_and_closing_without_a_record_leaves_no_file(tmp_path):
    """Issue 43, defect 9: an empty journal and its lock were left beside every recording."""
    rec = tmp_path / "walk.mp4"
    with Journal.open(rec) as j:
        assert not j.path.exists(), "no record yet: no journal file"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    with Journal.open(rec) as j:
        j.append({"n": 1})
        j.compact()                 # saved: nothing left to keep
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    with Journal.open(rec) as j:
        j.append({"n": 2})          # not saved: the record stays, the lock goes
    assert [p.name for p in tmp_path.iterdir()] == [j.path.name]
    with Journal.open(rec) as j:
        assert j.replay() == [{"n": 2}]


@pytest.mark.parametrize("planted", [".journal", ".journal.lock"])
def test_a_planted_journal_or_lock_link_is_refused_and_its_target_untouched(tmp_path, planted):
    """Issue 43, defect 14: the journal writes only regular files it owns."""
    from engine.journal import UnsafeJournal

    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    session = session_path_for(tmp_path / "walk.mp4")
    session.with_name(session.name + planted).symlink_to(victim)
    with pytest.raises(UnsafeJournal):
        with Journal.open(session) as j:
            j.append({"n": 1})
    assert victim.read_text() == "keep me"
