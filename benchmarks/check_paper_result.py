"""The paper's qualitative result on the synthetic benchmark (mapping-engine issue, item 7).

A measurement over rendered routes (about 4 minutes of rendering and describing on two
loaded cores), so it lives beside the benchmarks, out of the test command:

    python -m pytest -q benchmarks/check_paper_result.py

Small recordings (256x128, descriptor input height 128), a reverse and a crossing route,
the three methods of Table I with thresholds calibrated from each recording (the same
for all three). What must hold, as in the paper's Tables II-V:

* the spatial consistency check (``ours``) has higher precision than both simple variants;
* the panorama shift helps revisits from another heading: at the same threshold it raises
  the recall of pairs driven in reverse, and it raises the similarity of the same place
  seen at a crossing at 90 degrees (where the calibrated threshold is low enough that
  the simple threshold already finds every crossing pair, so recall cannot rise there).

Descriptor: ``effnet-vlad`` with ``layout="sectors"``, which is heading-sensitive as the
paper's DINOv2 features are. The paper's claim is about such a descriptor: plain VLAD
(``layout="global"``) pools away where things are, so a turned view matches about as
well with or without the shift, and the shift cannot raise recall (measured in
benchmarks/results/methods_paper.md: 0.90 -> 0.82 on crossings, 0.62 -> 0.62 reverse).
"sectors" is not the default layout: it also lets more near misses (1-3 m apart) through
``ours`` (held-out seeds 8, 9: precision 0.62 instead of 0.78), while ``verified`` is
about the same with either layout (1 false loop; 16/20 and 15/20 events).
"""

import numpy as np
import pytest

from benchmarks.harness import FPS, PAPER_METHODS, Case, Described, calibrated_params, evaluate_methods, sum_rows
from engine.frames import Frame
from engine.pipeline import DescribeSettings, describe_frames
from engine.synth import make_recording

ROUTES = [("reverse", "indoor"), ("crossing", "outdoor")]
OPTIONS = {"input_height": 128, "layout": "sectors"}


def describe(case: Case) -> Described:
    rec = make_recording(case.route, case.look, case.seed, width=case.width, height=case.width // 2, fps=FPS)
    by_shift = {}
    for shift in (True, False):
        settings = DescribeSettings(interval=1.0 / FPS, shift=shift, options=OPTIONS)
        frames = (Frame(k, float(t), rgb) for k, (t, rgb) in enumerate(zip(rec.stamps, rec.frames)))
        by_shift[shift] = describe_frames(frames, len(rec), settings, source=case.name)
    return Described(case, by_shift, case.poses())


@pytest.fixture(scope="module")
def described():
    return {r: describe(Case(*r, seed=0)) for r in ROUTES}


@pytest.fixture(scope="module")
def rows(described):
    out = []
    for d in described.values():
        out += evaluate_methods(d, PAPER_METHODS, calibrated_params(d, PAPER_METHODS))
    return out


def test_every_route_has_a_revisit_and_all_methods_ran(rows):
    assert len(rows) == len(ROUTES) * len(PAPER_METHODS)
    assert all(r.events_total >= 1 for r in rows)
    assert all(r.tp + r.fp + r.tn + r.fn == (r.nodes - 1) * (r.nodes - 2) // 2 for r in rows)


def test_ours_has_higher_precision_than_both_simple_variants(rows):
    ours = sum_rows(rows, "ours")
    assert ours["tp"] > 0
    assert ours["precision"] > sum_rows(rows, "simple")["precision"]
    assert ours["precision"] > sum_rows(rows, "shift-simple")["precision"]


def test_shift_raises_recall_of_reverse_drives_at_the_same_threshold(rows):
    sel = [r for r in rows if r.route == "reverse"]
    simple, shifted = sum_rows(sel, "simple"), sum_rows(sel, "shift-simple")
    assert simple["tp"] + simple["fn"] > 50
    # Measured 0.19 -> 0.36 (seed 0; seeds 1, 2: 0.19 -> 0.38, 0.07 -> 0.38).
    assert shifted["recall"] > 1.4 * simple["recall"]
    # ... and with fewer false loops, not by letting more of everything through.
    assert shifted["fp"] < simple["fp"]


def test_shift_does_not_lose_crossing_pairs(rows):
    sel = [r for r in rows if r.route == "crossing"]
    simple, shifted = sum_rows(sel, "simple"), sum_rows(sel, "shift-simple")
    assert simple["tp"] + simple["fn"] >= 2
    assert shifted["recall"] >= simple["recall"]
    assert shifted["tp"] > 0


def same_place_similarity(d: Described, shift: bool) -> np.ndarray:
    descs = d.by_shift[shift]
    x, y = d.poses.at(descs.stamps)
    i, j = np.triu_indices(len(descs), 20)   # revisits: at least 20 s apart
    same = np.hypot(x[i] - x[j], y[i] - y[j]) <= 1.0
    i, j = i[same], j[same]
    assert i.size >= 2
    return np.einsum("ij,ij->i", descs.vectors[i], descs.vectors[j])


@pytest.mark.parametrize("route", ROUTES)
def test_shift_raises_the_similarity_of_the_same_place_seen_from_another_heading(described, route):
    d = described[route]
    before, after = same_place_similarity(d, False), same_place_similarity(d, True)
    # Measured (mean): reverse indoor 0.37 -> 0.50, crossing outdoor 0.70 -> 0.77.
    assert after.mean() > before.mean() + 0.05
