"""Descriptors from any model map: an .npz with an unknown descriptor name and no columns."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.harness import random_walk_descriptors
from engine.cli import main
from engine.descriptors.base import Descriptors
from engine.params import MapParams
from engine.pipeline import build_map, descriptor_defaults


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """600 rows of 1024-D vectors, meta descriptor "my-own-vpr", nothing else."""
    v, origin = random_walk_descriptors(600, 1024, seed=4, revisit_share=0.3)
    n = v.shape[0]
    d = Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n), shifts=np.zeros(n, np.int64),
                    vectors=v, meta={"descriptor": "my-own-vpr"})
    path = tmp_path_factory.mktemp("foreign") / "x.npz"
    d.save(path)
    return path, origin


def test_unknown_descriptor_gets_thresholds_from_the_recording(foreign):
    path, _ = foreign
    th = descriptor_defaults(Descriptors.load(path))
    assert set(th) >= {"node_sim_th", "loop_sim_th"}
    assert 0.0 < th["loop_sim_th"] < 1.0 and 0.0 < th["node_sim_th"] < 1.0


def test_verified_calibrates_no_paper_threshold_it_does_not_read(foreign, monkeypatch):
    import engine.calibrate

    def refuse(*_args, **_kwargs):
        raise AssertionError("the paper's thresholds were calibrated for verified")

    monkeypatch.setattr(engine.calibrate, "paper_thresholds", refuse)
    path, _ = foreign
    descs = Descriptors.load(path)
    assert descriptor_defaults(descs, "verified") == {}
    assert build_map(descs, MapParams(method="verified")).node_count > 1


@pytest.mark.parametrize("method", ["ours", "simple", "verified"])
def test_build_map_maps_a_foreign_npz(foreign, method):
    path, origin = foreign
    descs = Descriptors.load(path)
    if method == "simple":
        descs.meta["shift"] = False
    topomap = build_map(descs, MapParams(method=method))
    assert 1 < topomap.node_count <= len(descs)


def test_cli_maps_a_foreign_npz(foreign, tmp_path, capsys):
    path, _ = foreign
    out = tmp_path / "y.graphml"
    code = main(["map", str(path), "-o", str(out), "--method", "ours", "-q"])
    assert code == 0, capsys.readouterr().err
    assert out.is_file() and "<graphml" in out.read_text()[:2000]


def test_integer_descriptors_are_normalised_and_the_user_is_told(foreign, tmp_path, capsys):
    """Issue 43 item 18: integer rows (another tool's quantised output) were used unnormalised,
    so the cosine thresholds saw lengths, not directions. Read as their directions, they give
    the map the same directions as unit floats give, and one line says so."""
    path, _ = foreign
    floats = Descriptors.load(path)
    ints = np.round(floats.vectors * 1000).astype(np.int32)
    raw = tmp_path / "ints.npz"
    np.savez(raw, stamps=floats.stamps, frames=floats.frames, shifts=floats.shifts, descriptors=ints,
             meta=np.array('{"descriptor": "my-own-vpr"}'))
    units = ints / np.linalg.norm(ints.astype(np.float64), axis=1, keepdims=True)
    unit_path = tmp_path / "units.npz"
    Descriptors(stamps=floats.stamps, frames=floats.frames, shifts=floats.shifts,
                vectors=units.astype(np.float32), meta={"descriptor": "my-own-vpr"}).save(unit_path)

    loaded = Descriptors.load(raw)
    assert np.allclose(np.linalg.norm(loaded.vectors, axis=1), 1.0, atol=1e-5)
    assert len(loaded.notes) == 1 and "normalised" in loaded.notes[0]
    assert Descriptors.load(unit_path).notes == []  # unit rows are left as they are, silently

    maps = {}
    for name, src in (("ints", raw), ("units", unit_path)):
        out = tmp_path / f"{name}.graphml"
        code = main(["map", str(src), "-o", str(out), "--method", "ours", "-q"])
        err = capsys.readouterr().err
        assert code == 0, err
        maps[name] = (out.read_text().count("<node "), err)
    assert maps["ints"][0] == maps["units"][0]
    lines = maps["ints"][1].strip().splitlines()
    assert len(lines) == 1 and "integers" in lines[0] and "normalised" in lines[0]
    assert maps["units"][1].strip() == ""


def test_whole_frame_numbers_written_as_floats_are_read(tmp_path):
    """Another tool may write frame numbers as floats; whole ones are read, silently."""
    n = 20
    v = random_walk_descriptors(n, 32, seed=1)[0]
    path = tmp_path / "float_frames.npz"
    np.savez(path, stamps=np.arange(n, dtype=np.float64), frames=np.arange(n, dtype=np.float64),
             shifts=np.zeros(n), descriptors=v, meta=np.array('{"descriptor": "my-own-vpr"}'))
    d = Descriptors.load(path)
    assert d.frames.dtype == np.int64 and list(d.frames) == list(range(n)) and d.notes == []
