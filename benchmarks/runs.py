"""The one table of benchmark runs: ``benchmarks/results/runs.csv``, one row per run.

A benchmark that measures places found on a family of recordings calls ``append_run`` once per
(family, seeds, method) it mapped; the date and the commit are added here. Columns:

- ``date`` (UTC, YYYY-MM-DD), ``commit`` (``git rev-parse --short HEAD``, with ``+dirty`` when
  the working tree has uncommitted changes to tracked files);
- ``family`` (``first`` = ``engine.synth``, ``second`` = ``engine.synth2``, ``real``), ``seeds``
  (``0-4``, ``160-164 170-174``; ``photos`` for the real panoramas), ``method``, ``runs``
  (recordings mapped);
- ``places`` (revisit events in the truth), ``places_found`` (found by an automatic loop),
  ``false_loops`` (loop arcs between nodes more than 1 m apart, or temporal neighbours),
  ``with_queue`` (found by an automatic loop or a candidate of the review queue), ``queue``
  (candidates left for a person) and ``false_in_queue`` (of them, not the same place);
- ``notes``: free text (what was different about the run: a parameter, a branch, "held out");
- added after ``notes`` (issue 41, the project's don't-care band, ``engine.evaluate.evaluate_band``;
  empty in older rows): ``true_loops`` (automatic loops joining views within 1 m, not temporal
  neighbours), ``dont_care_loops`` (1-2 m apart: neither right nor false), ``band_false_loops``
  (beyond 2 m, or between temporal neighbours). The band's places found / revisited are
  ``places_found`` / ``places`` (a place is found by a loop within 1 m either way), and
  ``false_loops`` keeps its meaning (the paper's 1 m: the band's don't-care loops included).

Older files whose header lacks the added columns are brought up to date by ``append_run``
(the header line alone is rewritten; old rows read the added cells as empty).

Rows dated up to 2026-11-27 were read from the Markdown tables that used to live in
``benchmarks/results/`` (each note names its file and line; read one with
``git show b45dfff:benchmarks/results/<file>``) and from the README's results table (its
commit: the one that brought the row into the README). Their ``commit`` is the one that added
the file, or the code commit the file names for that table. Rows before 2026-11-25 named
``verified`` were the first round's rule-based method, which is ``verified-rules`` today: they
are listed under that name.

    from runs import append_run            # benchmarks/ on sys.path, as the benchmarks have it
    append_run({"family": "second", "seeds": "250-255", "method": "verified", "runs": 42,
                "places": 113, "places_found": 99, "false_loops": 0, "with_queue": 103,
                "queue": 267, "false_in_queue": 258, "notes": "held out"})
"""

from __future__ import annotations

import csv
import datetime as _dt
import subprocess
from pathlib import Path

RUNS = Path(__file__).resolve().parent / "results" / "runs.csv"
COLUMNS = ("date", "commit", "family", "seeds", "method", "runs", "places", "places_found",
           "false_loops", "with_queue", "queue", "false_in_queue", "notes",
           "true_loops", "dont_care_loops", "band_false_loops")


def _commit() -> str:
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def seeds_text(seeds) -> str:
    """``[0, 1, 2, 3, 4, 8]`` -> ``"0-4 8"``."""
    seeds = sorted(set(int(s) for s in seeds))
    parts, i = [], 0
    while i < len(seeds):
        j = i
        while j + 1 < len(seeds) and seeds[j + 1] == seeds[j] + 1:
            j += 1
        parts.append(str(seeds[i]) if i == j else f"{seeds[i]}-{seeds[j]}")
        i = j + 1
    return " ".join(parts)


def append_run(row: dict, path: Path = RUNS) -> dict:
    """Append one run to ``runs.csv`` (the header first if the file is new); returns the row
    as written. ``date`` and ``commit`` are filled in unless given; ``seeds`` may be a list.
    Unknown keys are refused, so that a typo does not vanish."""
    unknown = set(row) - set(COLUMNS)
    if unknown:
        raise ValueError(f"runs.csv has no column {sorted(unknown)}; columns: {', '.join(COLUMNS)}")
    out = {c: "" for c in COLUMNS}
    out.update({k: v for k, v in row.items() if v is not None})
    if not isinstance(out["seeds"], str):
        out["seeds"] = seeds_text(out["seeds"])
    out["date"] = out["date"] or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d")
    out["commit"] = out["commit"] or _commit()
    path = Path(path)
    new = not path.exists() or path.stat().st_size == 0
    path.parent.mkdir(parents=True, exist_ok=True)
    if not new:
        _upgrade_header(path)
    with path.open("a", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, lineterminator="\n")
        if new:
            w.writeheader()
        w.writerow(out)
    return out


def _upgrade_header(path: Path) -> None:
    """An older header (the first columns of ``COLUMNS``, in order) is replaced by today's; the
    rows stay as they are (their missing last cells read as empty). Any other header is refused."""
    with path.open(newline="", encoding="utf-8") as f:
        first = f.readline()
        header = next(csv.reader([first]), [])
        if tuple(header) == COLUMNS:
            return
        if tuple(header) != COLUMNS[:len(header)]:
            raise ValueError(f"{path}: unexpected header {header}; expected {', '.join(COLUMNS)}")
        rest = f.read()
    ending = "\r\n" if first.endswith("\r\n") else "\n"
    path.write_text(",".join(COLUMNS) + ending + rest, encoding="utf-8", newline="")


def read_runs(path: Path = RUNS) -> list[dict]:
    """Every row of ``runs.csv``, oldest first (cells an older row lacks read as "")."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        return [{**dict.fromkeys(COLUMNS, ""), **{k: v for k, v in row.items() if k is not None}}
                for row in csv.DictReader(f, restval="")]


if __name__ == "__main__":   # the newest row per (family, seeds, method)
    latest: dict = {}
    for r in read_runs():
        latest[(r["family"], r["seeds"], r["method"])] = r
    for r in latest.values():
        print(",".join(r[c] for c in COLUMNS if c != "notes"))
