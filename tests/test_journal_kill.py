"""kill -9 at random moments loses no acknowledged decision (issue 16, finding 1).

A real subprocess (tests/journal_writer.py) journals a decision every 20 ms and says
``ack n`` once each is written; it is killed with SIGKILL at a random moment, 20 times
in a row (each new process continues the same journal). Every acknowledged decision
must be replayed, in order, and nothing is replayed twice. The one-decision-per-second
version is ``benchmarks/kill_test.py`` (a fresh interpreter per process: ``run_and_kill``).

Here each of the 20 processes is forked from one that has already imported the writer
(tests/fork_runner.py): a process of its own, opening the journal itself and killed with
SIGKILL like a fresh one, without a second or two of imports each.
"""

from __future__ import annotations

import json
import os
import queue
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from engine.journal import Journal

WRITER = Path(__file__).resolve().parent / "journal_writer.py"
ROOT = WRITER.parent.parent


def run_and_kill(session: Path, period: float, lifetime: float, writer: Path = WRITER) -> list[int]:
    """Start a writer, kill -9 it after ``lifetime`` seconds of writing; the acks it gave."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, str(writer), str(session), str(period)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    acks: list[int] = []
    ready = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            if line.startswith("ready"):
                ready.set()
            elif line.startswith("ack "):
                acks.append(int(line.split()[1]))
        ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert ready.wait(30), "the writer did not start"
    time.sleep(lifetime)
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    reader.join(10)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()[-2000:]
    return acks


class Forks:
    """tests/fork_runner.py for ``writer``: ``run_and_kill`` as above, in forked processes."""

    def __init__(self, writer: Path, log: Path):
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        self.log = log
        self._err = open(log, "w")
        self.proc = subprocess.Popen([sys.executable, str(WRITER.parent / "fork_runner.py"), str(writer)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err,
                                     text=True, env=env)
        self.lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        assert self._next(60) == "loaded", self.log.read_text()[-2000:]

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.strip())
        self.lines.put(None)

    def _next(self, timeout: float):
        try:
            line = self.lines.get(timeout=timeout)
        except queue.Empty:
            line = None
        assert line is not None, f"the fork runner stopped: {self.log.read_text()[-2000:]}"
        return line

    def run_and_kill(self, session: Path, period: float, lifetime: float) -> list[int]:
        self.proc.stdin.write(json.dumps([str(session), str(period)]) + "\n")
        self.proc.stdin.flush()
        first = self._next(30)
        assert first.startswith("pid "), first
        pid = int(first.split()[1])
        acks: list[int] = []
        line = self._next(30)
        assert line == "ready", f"the writer did not start: {line} {self.log.read_text()[-2000:]}"
        time.sleep(lifetime)
        os.kill(pid, signal.SIGKILL)
        while not (line := self._next(10)).startswith("exit "):
            assert line.startswith("ack "), line
            acks.append(int(line.split()[1]))
        assert line == f"exit {pid} {-signal.SIGKILL}", (line, self.log.read_text()[-2000:])
        return acks

    def close(self) -> None:
        self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)
        self._err.close()


def test_twenty_random_kills_lose_no_decision(tmp_path):
    session = tmp_path / "walk.mp4.panotopo.json"
    rng = random.Random()  # random moments on purpose: any moment must be safe
    acked: list[int] = []
    forks = Forks(WRITER, tmp_path / "writer.log")
    try:
        for _ in range(20):
            acked += forks.run_and_kill(session, period=0.02, lifetime=rng.uniform(0.03, 0.2))
    finally:
        forks.close()
    journal = Journal.open(session)
    try:
        replayed = [r["decision"] for r in journal.replay()]
    finally:
        journal.close()
    assert len(acked) > 40, "too few decisions were made to test anything"
    lost = sorted(set(acked) - set(replayed))
    assert lost == []
    assert replayed == sorted(set(replayed))      # in order, none twice


def test_twenty_random_kills_of_the_app_model_lose_no_decision(tmp_path):
    """The same through what the window runs: the review queue of the Qt-free app model
    (gui.model) confirms candidates with the recording's journal attached."""
    from tests.app_decider import candidate_map, key_of
    from gui.model import journal as records

    session = tmp_path / "walk.mp4.panotopo.json"
    rng = random.Random()
    acked: list[int] = []
    forks = Forks(WRITER.parent / "app_decider.py", tmp_path / "decider.log")
    try:
        for _ in range(20):
            acked += forks.run_and_kill(session, period=0.02, lifetime=rng.uniform(0.05, 0.3))
    finally:
        forks.close()
    journal = Journal.open(session)
    try:
        decisions = records.replay(journal.replay())
    finally:
        journal.close()
    reopened = candidate_map()
    reopened.apply_decisions(decisions)
    confirmed = {(reopened.graph.nodes[u]["frame"], reopened.graph.nodes[v]["frame"])
                 for u, v, d in reopened.loops(("confirmed",))}
    assert len(acked) > 20, "too few decisions were made to test anything"
    lost = [n for n in acked if key_of(n) not in confirmed]
    assert lost == []
