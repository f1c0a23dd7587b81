"""A session file is data: every malformed field gets one line naming it; nothing in it
can make panotopo write a file (issue 16, findings 5, 10 and 15)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from engine.errors import InputError
from engine.session import Session


def _write(tmp_path: Path, **fields) -> Path:
    data = {"format": "panotopo-session", "version": 1, "input": "walk.mp4"}
    data.update(fields)
    path = tmp_path / "walk.mp4.panotopo.json"
    path.write_text(json.dumps(data))
    return path


# (fields, the field the message must name)
BAD_FIELDS = [
    ({"decisions": {"manual": [{"frames": ["a", "b"]}]}}, "decisions.manual[0].frames"),
    ({"decisions": {"loops": [{"frames": [1, 2, 3], "status": "confirmed"}]}}, "decisions.loops[0].frames"),
    ({"decisions": {"loops": [{"frames": [1, 20], "status": "maybe"}]}}, "decisions.loops[0].status"),
    ({"decisions": {"loops": [{"frames": [-4, 20], "status": "confirmed"}]}}, "decisions.loops[0].frames"),
    ({"decisions": {"manual": [{"frames": [1, 20], "yaw": "north"}]}}, "decisions.manual[0].yaw"),
    ({"decisions": {"labels": [{"frame": 3, "label": 7}]}}, "decisions.labels[0].label"),
    ({"decisions": {"labels": "door"}}, "decisions.labels"),
    ({"describe": {"interval": "fast"}}, "describe.interval"),
    ({"describe": {"interval": float("nan")}}, "describe.interval"),
    ({"describe": {"shift": "yes"}}, "describe.shift"),
    ({"describe": {"options": {"input_height": 16000}}}, "describe.options.input_height"),
    ({"describe": {"options": ["input_height"]}}, "describe.options"),
    ({"params": {"loop_sim_th": 7}}, "params.loop_sim_th"),
    ({"params": {"node_sim_th": "high"}}, "params.node_sim_th"),
    ({"params": {"method": "magic"}}, "params.method"),
    ({"view": {"frame": "twelve"}}, "view.frame"),
    ({"view": {"selected": [1]}}, "view.selected"),
    ({"poses": {"path": 3}}, "poses"),
    ({"version": "1"}, "version"),
]


@pytest.mark.parametrize("fields, named", BAD_FIELDS)
def test_a_malformed_field_gets_one_line_naming_it(tmp_path, fields, named):
    path = _write(tmp_path, **fields)
    with pytest.raises(InputError) as err:
        Session.load(path)
    message = str(err.value)
    assert named in message and "\n" not in message


def test_a_version_given_as_text_is_not_called_newer(tmp_path):
    with pytest.raises(InputError) as err:
        Session.load(_write(tmp_path, version="1"))
    assert "newer" not in str(err.value)


def test_a_session_cannot_name_a_file_to_write(tmp_path):
    """Finding 5: ``save_vocabulary`` in a session overwrote any file the user could write."""
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    path = _write(tmp_path, describe={"descriptor": "anyloc-vlad",
                                      "options": {"save_vocabulary": str(victim)}})
    with pytest.raises(InputError, match="save_vocabulary"):
        Session.load(path)
    assert victim.read_text() == "keep me"


@pytest.mark.parametrize("weights", ["/nonexistent/dinov2.pth", "/dev/zero", "."])
def test_a_weights_path_must_be_an_existing_regular_file(tmp_path, weights):
    path = _write(tmp_path, describe={"descriptor": "anyloc-gem", "options": {"weights": weights}})
    with pytest.raises(InputError, match="weights"):
        Session.load(path)


def test_a_session_cannot_turn_on_downloads(tmp_path):
    path = _write(tmp_path, describe={"descriptor": "anyloc-gem", "options": {"allow_download": True}})
    assert "allow_download" not in Session.load(path).describe["options"]


def test_a_good_session_keeps_its_fields(tmp_path):
    dec = {"loops": [{"frames": [3, 40], "status": "confirmed"}],
           "manual": [{"frames": [5, 90], "yaw": 12.5}], "labels": [{"frame": 7, "label": "door"}]}
    path = _write(tmp_path, describe={"descriptor": "effnet-vlad", "interval": 0.5,
                                      "options": {"input_height": 64}},
                  params={"method": "ours", "loop_sim_th": 0.6}, decisions=dec, view={"frame": 3})
    s = Session.load(path)
    assert s.decisions == dec
    assert s.describe["options"] == {"input_height": 64}
    assert s.map_params().loop_sim_th == 0.6


def _registry():
    from engine.descriptors import REGISTRY

    return sorted(REGISTRY)


@pytest.mark.parametrize("descriptor", _registry())
def test_no_descriptor_lets_a_file_turn_on_a_download(tmp_path, descriptor):
    """Issue 43, defect 13: megaloc and boq returned their options before the filter."""
    path = _write(tmp_path, describe={"descriptor": descriptor, "options": {"allow_download": True}})
    assert "allow_download" not in Session.load(path).describe.get("options", {})


@pytest.mark.parametrize("descriptor", _registry())
@pytest.mark.parametrize("option", ["save_vocabulary", "trust_repo", "hub_url"])
def test_no_descriptor_takes_an_option_that_would_write_or_run(tmp_path, descriptor, option):
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    path = _write(tmp_path, describe={"descriptor": descriptor, "options": {option: str(victim)}})
    with pytest.raises(InputError, match=option):
        Session.load(path)
    assert victim.read_text() == "keep me"


def test_an_unknown_descriptor_in_a_file_is_named(tmp_path):
    path = _write(tmp_path, describe={"descriptor": "fetch-from-the-web", "options": {"input_height": 64}})
    with pytest.raises(InputError, match="describe.descriptor"):
        Session.load(path)


def test_a_session_of_the_retired_method_opens_with_the_one_that_replaced_it():
    import warnings

    from engine.session_fields import check_params

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = check_params({"method": "verified-rules", "long_runs": True, "retrieval_k": 12})
    assert out["method"] == "verified" and "long_runs" not in out and out["retrieval_k"] == 12
    assert len(caught) == 1 and "verified-rules" in str(caught[0].message)
