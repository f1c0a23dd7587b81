"""The pair view: both panoramas aligned by the yaw, matched features drawn between them."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QPointF, Qt  # noqa: E402

from engine.sources import open_source  # noqa: E402
from gui.frame_cache import FrameCache  # noqa: E402
from gui.pair_evidence import PairMatches  # noqa: E402
from gui.pair_view import PairView  # noqa: E402
from tests.gui_maps import make_doc, pano_folder  # noqa: E402

W = 256
ROLL = 64      # frame 15 is frame 0 turned by a quarter


@pytest.fixture
def pair(qtbot, tmp_path):
    folder, frames = pano_folder(tmp_path / "frames", n=20, revisit=(0, 15), roll=ROLL, width=W)
    doc = make_doc(None, [(0, 15, "candidate"), (3, 10, "auto")], n=20)
    cache = FrameCache(open_source(folder))
    view = PairView(doc, cache)
    qtbot.addWidget(view)
    view.resize(700, 520)
    view.show()
    qtbot.waitExposed(view)
    yield view, cache, frames
    cache.source.close()


def _true_matches(cache, k_inliers: int = 12, k_outliers: int = 5, seed: int = 0) -> PairMatches:
    """Matches between frame 0 and its turned copy 15, in SHIFTED-frame fractions as the geometry gives them."""
    rng = np.random.default_rng(seed)
    a, b = cache.get(0), cache.get(15)
    h = a.rgb.shape[0]
    cols = rng.integers(0, W, size=k_inliers + k_outliers).astype(float)
    rows = rng.integers(5, h - 5, size=cols.size).astype(float)
    cols_b = cols + ROLL
    cols_b[k_inliers:] = rng.integers(0, W, size=k_outliers)   # outliers land anywhere
    uv_a = np.stack([np.mod(cols - a.shift, W) / W, rows / h], axis=1)
    uv_b = np.stack([np.mod(cols_b - b.shift, W) / W, rows / h], axis=1)
    mask = np.arange(cols.size) < k_inliers
    return PairMatches(uv_a=uv_a, uv_b=uv_b, inlier_mask=mask, yaw=None, inlier_ratio=k_inliers / cols.size)


def test_candidate_is_aligned_with_the_query_without_geometry(pair):
    view, cache, frames = pair
    view.matches_for = None   # no two-view geometry for this pair
    view.show_pair((0, 15))
    assert view.yaw is not None and abs(abs(view.yaw) - 90) < 3, "a quarter turn is found"
    query, cand = view.query_image.image, view.cand_image.image
    assert query.shape == cand.shape
    assert np.abs(query.astype(int) - cand.astype(int)).mean() < 8, "the candidate is rolled to match the query"
    assert "no feature matches" in view.evidence.text()
    assert "similarity" in view.evidence.text()


def test_matches_are_drawn_between_the_same_points_in_two_colours(pair):
    view, cache, _ = pair
    matches = _true_matches(cache)
    view.matches_for = lambda key: matches if tuple(key) == (0, 15) else None
    view.show_pair((0, 15))
    inliers, outliers = view.match_segments_shown()
    assert len(inliers) == 12 and len(outliers) == 5
    # Aligned: each inlier joins a point on the query to the same point of the candidate (drawn
    # below or beside it: less its offset).
    dx, dy = view.cand_offset
    assert dx > 0 or dy > 0
    assert np.abs(inliers[:, 0, 0] - (inliers[:, 1, 0] - dx)).max() < 2.5
    assert np.abs(inliers[:, 0, 1] - (inliers[:, 1, 1] - dy)).max() < 1e-6
    assert "12/17" in view.evidence.text()
    pen_in, pen_out = view.inlier_item.opts["pen"].color(), view.outlier_item.opts["pen"].color()
    assert pen_in != pen_out
    view.show_matches.setChecked(False)
    assert len(view.inlier_item.getData()[0] if view.inlier_item.getData()[0] is not None else []) == 0
    view.show_matches.setChecked(True)
    view.show_pair((3, 10))
    assert view.match_segments_shown()[0].size == 0, "another pair does not keep the old matches"


def test_loop_evidence_numbers_are_shown(pair):
    view, _, _ = pair
    view.matches_for = None   # the numbers stored on the loop arc
    g = view.doc.topomap.graph
    g.edges["n3", "n10"].update(score=4.2, matches=60, inliers=37, inlier_ratio=0.61, support=5.5,
                                step_inliers=33, closure=1.25)
    view.doc._rows = None
    view.show_pair((3, 10))
    text = view.evidence.text()
    assert "4.20" in text and "37/60" in text and "61 %" in text and "support 5.5" in text
    assert "path shares 33" in text and "within 1.2 node steps" in text


def test_real_matches_of_a_revisit_are_aligned_inliers(pair, qtbot):
    pytest.importorskip("engine.sphere")
    view, _, _ = pair
    view.show_pair((0, 15))   # the view's own match cache: features extracted, two-view geometry fitted
    assert view.matches is None and "matching features" in view.evidence.text(), "computed in the background"
    # the matches arrive after the frames and the background matching, whichever is last
    qtbot.waitUntil(lambda: view.matches is not None or bool(view.match_cache.errors), timeout=20_000)
    assert view.matches is not None, view.match_cache.errors
    inliers, outliers = view.match_segments_shown()
    assert len(inliers) >= 20 and len(inliers) > 3 * len(outliers), "a revisit has many inliers"
    dx, dy = view.cand_offset
    off = np.abs(inliers[:, 0] - (inliers[:, 1] - np.array([dx, dy])))
    off[:, 0] = np.minimum(off[:, 0], W - off[:, 0])   # across the seam
    assert np.median(off) < 2.0, "inliers join the same points of the aligned panoramas"
    assert f"{len(inliers)}/{len(inliers) + len(outliers)}" in view.evidence.text()


def test_a_wide_short_view_puts_the_pair_side_by_side(pair, qtbot):
    view, _, _ = pair
    view.show_pair((0, 15))
    assert not view.side_by_side
    view.resize(1000, 260)
    qtbot.wait(20)
    assert view.side_by_side and view.cand_offset[0] > 0


def test_wheel_zooms_and_double_click_shows_the_whole_pair(pair, qtbot):
    view, _, _ = pair
    view.show_pair((0, 15))
    whole = view.view.viewRect()
    view.view.scaleBy((0.3, 0.3))
    assert view.view.viewRect().width() < 0.5 * whole.width()
    centre = view.canvas.mapFromScene(view.view.mapViewToScene(QPointF(W / 2, 64)))
    qtbot.mouseDClick(view.canvas.viewport(), Qt.LeftButton, pos=centre)
    assert abs(view.view.viewRect().width() - whole.width()) < 0.05 * whole.width()


def test_the_yaw_of_a_pair_comes_from_its_features(pair):
    pytest.importorskip("engine.sphere")
    from gui.pair_evidence import pair_yaw

    view, cache, _ = pair
    expected = 360.0 * ROLL / W     # frame 15 is frame 0 turned by ROLL columns
    m = view.match_cache((0, 15))
    assert m is not None and m.yaw is not None
    assert abs((m.yaw - expected + 180) % 360 - 180) < 3
    yaw = pair_yaw(view.doc, cache, (0, 15), view.match_cache)
    assert abs((yaw - expected + 180) % 360 - 180) < 3


def test_matches_from_the_runs_feature_table(pair, qtbot):
    """The run keeps the features of each shifted frame; the view draws those, aligned."""
    pytest.importorskip("engine.sphere")
    from engine.features import FeatureTable, extract
    from engine.shift import apply_shift

    view, cache, _ = pair
    descs = view.doc.descs
    descs.shifts = np.array([cache.get(i).shift for i in range(len(descs))], dtype=np.int64)
    descs.features = FeatureTable.from_list([extract(apply_shift(cache.get(i).rgb, int(descs.shifts[i])))
                                             for i in range(len(descs))])
    calls = []
    original = descs.features.of
    descs.features.of = lambda i: calls.append(i) or original(i)
    view.show_pair((0, 15))
    # the matches arrive after the frames and the background matching, whichever is last
    qtbot.waitUntil(lambda: view.matches is not None or bool(view.match_cache.errors), timeout=60_000)   # its time-outs under load were the lost-callback race (test below)
    assert view.matches is not None, view.match_cache.errors
    assert sorted(calls) == [0, 15], "the stored features are used, none extracted again"
    inliers, _ = view.match_segments_shown()
    dx, dy = view.cand_offset
    off = np.abs(inliers[:, 0] - (inliers[:, 1] - np.array([dx, dy])))
    off[:, 0] = np.minimum(off[:, 0], W - off[:, 0])
    assert len(inliers) >= 20 and np.median(off) < 2.0


def test_matches_that_finish_before_their_callback_is_registered_are_shown(pair, qtbot):
    """On a loaded machine the worker can finish a pair before the UI thread goes on, its
    done callback running at once inside the request: the matches must still show."""
    view, _, _ = pair

    def run_now(fn, done=None, failed=None, **_kw):   # the worker at its fastest: done before submit returns
        done(fn())
        return 0

    view.match_worker.submit = run_now
    view.show_pair((0, 15))
    qtbot.waitUntil(lambda: view.matches is not None or bool(view.match_cache.errors), timeout=10_000)
    assert view.matches is not None, view.match_cache.errors
    assert "matching features" not in view.evidence.text()
