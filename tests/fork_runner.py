"""Runs a writer script's ``main()`` in a new process per request, its imports done once (used by
test_journal_kill.py; not a test itself).

``python tests/fork_runner.py SCRIPT`` imports SCRIPT (tests/journal_writer.py or
tests/app_decider.py: their imports are what takes a fresh interpreter a second or two), says
``loaded``, then for each line ``["ARG", ...]`` on stdin forks a child that runs SCRIPT's
``main()`` with those arguments, says ``pid N``, waits for the child to end and says
``exit N CODE`` (CODE as ``subprocess`` gives it: -9 for SIGKILL). The child is a process of its
own that opens its journal itself, after the fork; it writes its ``ready`` and ``ack n`` lines on
the same stdout, all of them before its ``exit`` line.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    script = sys.argv[1]
    spec = importlib.util.spec_from_file_location("forked_writer", script)
    writer = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(writer)
    print("loaded", flush=True)
    while True:
        line = sys.stdin.readline()
        if not line:
            return
        argv = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:   # the child: the writer, until it is killed
            code = 1
            try:
                sys.argv = [script, *argv]
                writer.main()
                code = 0
            except BaseException:
                traceback.print_exc()
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        print(f"pid {pid}", flush=True)
        _, status = os.waitpid(pid, 0)
        print(f"exit {pid} {os.waitstatus_to_exitcode(status)}", flush=True)


if __name__ == "__main__":
    main()
