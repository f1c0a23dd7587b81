"""Issue 16, finding 8: a checkpoint fetched with --allow-download is data, never code.

The real torch hub download code runs against a local file:// address (nothing leaves the
machine) that serves a pickle whose loading would run a payload; it must be refused."""

import pathlib

import pytest
import torch

from engine.descriptors import dinov2
from engine.errors import InputError


class _Payload:
    def __init__(self, marker: str):
        self.marker = marker

    def __reduce__(self):        # unpickling this object would create the marker file
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def test_a_downloaded_checkpoint_that_carries_code_is_refused_and_never_run(tmp_path, monkeypatch):
    marker = tmp_path / "payload-ran"
    served = tmp_path / "served.pth"
    torch.save({"pos_embed": _Payload(str(marker))}, served)
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch-home"))     # empty hub cache
    monkeypatch.setattr(dinov2.Arch, "url", property(lambda self: served.as_uri()))
    with pytest.raises(InputError) as err:
        dinov2.load_dinov2("vits14", allow_download=True)
    assert "\n" not in str(err.value)
    assert not marker.exists()
