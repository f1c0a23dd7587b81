"""MegaLoc and BoQ (DINOv2) descriptors: official weight layouts, tiny random-weight models
saved in those layouts, loaded through --weights / the torch hub cache, and `panotopo describe`."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from engine.descriptors import dinov2, get, names
from engine.descriptors.boq import BoQ, BoQNet
from engine.descriptors.megaloc import MegaLoc, MegaLocNet, sinkhorn_log
from engine.errors import InputError

TINY = dinov2.Arch("tiny", "ViT-64x2/14", 64, 2, 1, "mlp", 0)   # 64 channels, 2 blocks, 1 head
H = 112  # input height in the tests: 8 x 16 = 128 patches (MegaLoc needs more than its clusters)


def meta_shapes(module_factory) -> dict[str, tuple]:
    with torch.device("meta"):
        return {k: tuple(v.shape) for k, v in module_factory().state_dict().items()}


def dinov2_shapes(prefix: str, mask_token: bool = True) -> dict[str, tuple]:
    shapes = meta_shapes(lambda: dinov2.DinoVisionTransformer(dinov2.get_arch("vitb14")))
    return {prefix + k: v for k, v in shapes.items() if mask_token or k != "mask_token"}


def official_megaloc_head_shapes() -> dict[str, tuple]:
    """aggregator.* of MegaLoc's model.safetensors, written out from megaloc_model.py's defaults
    (768 channels, 64 clusters x 256, 256-d token, 512 hidden, 8448 out)."""
    a = "aggregator.agg."
    return {
        a + "token_features.0.weight": (512, 768), a + "token_features.0.bias": (512,),
        a + "token_features.2.weight": (256, 512), a + "token_features.2.bias": (256,),
        a + "cluster_features.0.weight": (512, 768, 1, 1), a + "cluster_features.0.bias": (512,),
        a + "cluster_features.3.weight": (256, 512, 1, 1), a + "cluster_features.3.bias": (256,),
        a + "score.0.weight": (512, 768, 1, 1), a + "score.0.bias": (512,),
        a + "score.3.weight": (64, 512, 1, 1), a + "score.3.bias": (64,),
        a + "dust_bin": (),
        "aggregator.linear.weight": (8448, 64 * 256 + 256), "aggregator.linear.bias": (8448,),
    }


def official_boq_head_shapes() -> dict[str, tuple]:
    """aggregator.* of BoQ's dinov2_12288.pth, written out from hubconf.py (in 768, proj 384,
    64 queries, 2 layers, row_dim 32) and torch's encoder/attention parameter names."""
    d = 384
    shapes = {"aggregator.proj_c.weight": (d, 768, 3, 3), "aggregator.proj_c.bias": (d,),
              "aggregator.norm_input.weight": (d,), "aggregator.norm_input.bias": (d,),
              "aggregator.fc.weight": (32, 128), "aggregator.fc.bias": (32,)}
    for i in range(2):
        b = f"aggregator.boqs.{i}."
        shapes[b + "queries"] = (1, 64, d)
        for attn in ("encoder.self_attn.", "self_attn.", "cross_attn."):
            shapes.update({b + attn + "in_proj_weight": (3 * d, d), b + attn + "in_proj_bias": (3 * d,),
                           b + attn + "out_proj.weight": (d, d), b + attn + "out_proj.bias": (d,)})
        shapes.update({b + "encoder.linear1.weight": (4 * d, d), b + "encoder.linear1.bias": (4 * d,),
                       b + "encoder.linear2.weight": (d, 4 * d), b + "encoder.linear2.bias": (d,)})
        for norm in ("encoder.norm1.", "encoder.norm2.", "norm_q.", "norm_out."):
            shapes.update({b + norm + "weight": (d,), b + norm + "bias": (d,)})
    return shapes


def randomised(net: torch.nn.Module, seed: int) -> torch.nn.Module:
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for _, p in net.named_parameters():
            p.copy_(torch.randn(p.shape, generator=gen) * 0.05 + (1.0 if p.ndim == 1 and p.numel() == 64 else 0.0))
    return net.eval()


@pytest.fixture(autouse=True)
def empty_caches(tmp_path, monkeypatch):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch_home"))
    monkeypatch.setenv("HF_HOME", str(tmp_path / "hf_home"))
    monkeypatch.delenv("HF_HUB_CACHE", raising=False)


@pytest.fixture(scope="module")
def megaloc_tiny(tmp_path_factory) -> tuple[str, str]:
    """(model.safetensors in the 2026 layout, megaloc.torch in the v1.0 layout) of one tiny model."""
    from safetensors.torch import save_file

    net = randomised(MegaLocNet(TINY, clusters=4, cluster_dim=8, token_dim=8, hidden=16, out_dim=8448), 1)
    state = {k: v.contiguous() for k, v in net.state_dict().items() if k != "backbone.mask_token"}
    folder = tmp_path_factory.mktemp("megaloc")
    save_file(state, str(folder / "model.safetensors"))
    legacy = {("backbone.model." + k[len("backbone."):] if k.startswith("backbone.") else k): v
              for k, v in net.state_dict().items()}
    torch.save(legacy, folder / "megaloc.torch")
    return str(folder / "model.safetensors"), str(folder / "megaloc.torch")


@pytest.fixture(scope="module")
def boq_tiny(tmp_path_factory) -> str:
    """Tiny BoQ in the official layout; 64 channels x 192 = 12,288 numbers like the real one."""
    net = randomised(BoQNet(TINY, proj=64, queries=8, layers=2, row_dim=192), 2)
    path = tmp_path_factory.mktemp("boq") / "dinov2_12288.pth"
    torch.save(net.state_dict(), path)
    return str(path)


def panoramas(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (64, 128, 3)).astype(np.uint8)
    return [np.roll(base, 16 * i, axis=1) for i in range(n)]


# ---------------------------------------------------------------- layouts

def test_megaloc_module_has_the_official_names_and_shapes():
    shapes = meta_shapes(lambda: MegaLocNet(dinov2.get_arch("vitb14")))
    assert shapes == {**dinov2_shapes("backbone."), **official_megaloc_head_shapes()}


def test_boq_module_has_the_official_names_and_shapes():
    shapes = meta_shapes(lambda: BoQNet(dinov2.get_arch("vitb14")))
    assert shapes == {**dinov2_shapes("backbone.dino."), **official_boq_head_shapes()}


def test_sinkhorn_columns_sum_to_about_one_and_dustbin_takes_the_rest():
    scores = torch.randn(2, 4, 50)
    p = sinkhorn_log(scores, torch.tensor(1.0), iters=50).exp()
    full = p.sum(dim=1)                                   # clusters only (dustbin dropped)
    assert p.shape == (2, 4, 50) and torch.all(full < 1.0 + 1e-4)
    # With converged marginals each cluster row carries 1/(n+m) of the mass, scaled by n+m.
    assert torch.allclose(p.sum(dim=2), torch.ones(2, 4), atol=1e-3)


# ---------------------------------------------------------------- loading and describing

def test_both_registered():
    assert {"megaloc", "boq"} <= set(names())


@pytest.mark.parametrize("which", [0, 1])
def test_megaloc_loads_both_official_formats_and_gives_8448_unit_rows(megaloc_tiny, which):
    model = get("megaloc", weights=megaloc_tiny[which], input_height=H, batch_size=2)
    out = model.describe(iter(panoramas(3)), 3)
    assert out.shape == (3, 8448) and out.dtype == np.float32
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-5)
    assert model.settings()["input_size"] == [H, 2 * H]


def test_megaloc_formats_give_the_same_descriptors(megaloc_tiny):
    a = MegaLoc(weights=megaloc_tiny[0], input_height=H).describe(iter(panoramas(2)), 2)
    b = MegaLoc(weights=megaloc_tiny[1], input_height=H).describe(iter(panoramas(2)), 2)
    assert np.allclose(a, b, atol=1e-6)


def test_boq_gives_12288_unit_rows_and_batches_do_not_matter(boq_tiny):
    imgs = panoramas(3)
    one = BoQ(weights=boq_tiny, input_height=H, batch_size=1, device="cpu").describe(iter(imgs), 3)
    three = BoQ(weights=boq_tiny, input_height=H, batch_size=3, device="cpu").describe(iter(imgs), 3)
    assert one.shape == (3, 12288) and np.allclose(np.linalg.norm(one, axis=1), 1.0, atol=1e-5)
    assert np.allclose(one, three, atol=1e-5)


def test_official_file_in_the_torch_hub_cache_is_found(boq_tiny, tmp_path):
    cache = tmp_path / "torch_home" / "hub" / "checkpoints"
    cache.mkdir(parents=True)
    (cache / "dinov2_12288.pth").symlink_to(boq_tiny)
    assert BoQ(input_height=H).weights_path == cache / "dinov2_12288.pth"


def test_megaloc_in_the_hugging_face_cache_is_found(megaloc_tiny, tmp_path):
    snap = tmp_path / "hf_home" / "hub" / "models--gberton--MegaLoc" / "snapshots" / "abc123"
    snap.mkdir(parents=True)
    (snap / "model.safetensors").symlink_to(megaloc_tiny[0])
    assert MegaLoc(input_height=H).weights_path == snap / "model.safetensors"


@pytest.mark.parametrize("cls, file", [(MegaLoc, "megaloc.torch"), (BoQ, "dinov2_12288.pth")])
def test_missing_weights_say_which_file_and_where(cls, file):
    with pytest.raises(InputError) as err:
        cls()
    msg = str(err.value)
    assert file in msg and "--weights" in msg and "checkpoints" in msg and "\n" not in msg


def test_wrong_layouts_are_one_clear_line(megaloc_tiny, boq_tiny, tmp_path):
    with pytest.raises(InputError, match=r"not a MegaLoc checkpoint \(no DINOv2 backbone"):
        MegaLoc(weights=boq_tiny, input_height=H).describe(iter(panoramas(1)), 1)
    with pytest.raises(InputError, match=r"not a BoQ \(DINOv2\) checkpoint"):
        BoQ(weights=megaloc_tiny[1], input_height=H).describe(iter(panoramas(1)), 1)
    # The right keys with one wrong shape.
    state = torch.load(boq_tiny, weights_only=True)
    state["aggregator.norm_input.weight"] = torch.ones(65)
    bad = tmp_path / "bad.pth"
    torch.save(state, bad)
    with pytest.raises(InputError, match=r"aggregator.norm_input.weight has shape \(65,\), expected \(64,\)"):
        BoQ(weights=str(bad), input_height=H).describe(iter(panoramas(1)), 1)
    bad.write_bytes(open(boq_tiny, "rb").read()[:1000])
    with pytest.raises(InputError, match="truncated"):
        BoQ(weights=str(bad), input_height=H).describe(iter(panoramas(1)), 1)


def test_options_of_other_descriptors_are_refused(boq_tiny):
    with pytest.raises(InputError, match="no option 'backbone'"):
        get("boq", weights=boq_tiny, backbone="vitb14")


def test_cli_describe_and_map_on_a_synthetic_video(megaloc_tiny, boq_tiny, tmp_path):
    import networkx as nx

    from engine.cli import main
    from engine.synth import make_recording, write_recording

    rec = make_recording("reverse", look="indoor", seed=1, width=128, height=64, fps=1.0, max_frames=6)
    video = write_recording(rec, tmp_path / "rec", formats=["video"])["video"]
    for name, weights, dim in [("megaloc", megaloc_tiny[0], 8448), ("boq", boq_tiny, 12288)]:
        common = ["--descriptor", name, "--weights", weights, "--input-height", str(H), "--no-cache", "-q"]
        npz = tmp_path / f"{name}.npz"
        assert main(["describe", str(video), "-o", str(npz), *common]) == 0
        with np.load(npz) as z:
            d = z["descriptors"]
        assert d.shape[1] == dim and len(d) >= 4
        assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
        out = tmp_path / f"{name}.graphml"
        # No calibrated thresholds: the default method calibrates them from the recording.
        assert main(["map", str(npz), "-o", str(out), "-q"]) == 0
        assert nx.read_graphml(out).number_of_nodes() >= 1
