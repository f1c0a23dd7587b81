"""AnyLoc-VLAD / AnyLoc-GeM on DINOv2, with random-weight checkpoints in the official format."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from engine.descriptors import dinov2
from engine.descriptors.anyloc import (
    AnyLocGeM, AnyLocVLAD, anyloc_vlad, gem, input_size, load_vocabulary, pca_project,
    pick_device, preprocess, save_vocabulary,
)
from engine.errors import Cancelled, InputError

H = 56  # input height for the tests: 4 x 8 patches


def official_vits14_shapes() -> dict[str, tuple]:
    """Key -> shape of the published dinov2_vits14_pretrain.pth, written out from the architecture."""
    d, hidden = 384, 1536
    shapes = {
        "cls_token": (1, 1, d), "pos_embed": (1, 37 * 37 + 1, d), "mask_token": (1, d),
        "patch_embed.proj.weight": (d, 3, 14, 14), "patch_embed.proj.bias": (d,),
        "norm.weight": (d,), "norm.bias": (d,),
    }
    for i in range(12):
        b = f"blocks.{i}."
        shapes.update({
            b + "norm1.weight": (d,), b + "norm1.bias": (d,),
            b + "attn.qkv.weight": (3 * d, d), b + "attn.qkv.bias": (3 * d,),
            b + "attn.proj.weight": (d, d), b + "attn.proj.bias": (d,),
            b + "ls1.gamma": (d,),
            b + "norm2.weight": (d,), b + "norm2.bias": (d,),
            b + "mlp.fc1.weight": (hidden, d), b + "mlp.fc1.bias": (hidden,),
            b + "mlp.fc2.weight": (d, hidden), b + "mlp.fc2.bias": (d,),
            b + "ls2.gamma": (d,),
        })
    return shapes


def shapes_of(backbone: str) -> dict[str, tuple]:
    with torch.device("meta"):  # no memory, no init: ViT-G has 1.1e9 parameters
        model = dinov2.DinoVisionTransformer(dinov2.get_arch(backbone))
    return {k: tuple(v.shape) for k, v in model.state_dict().items()}


def images(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (32, 64, 3)).astype(np.uint8)
    out = []
    for i in range(n):  # related panoramas: the base rolled, plus noise
        img = np.roll(base, 8 * i, axis=1).repeat(2, 0).repeat(2, 1)
        out.append(np.clip(img + rng.normal(0, 10, img.shape), 0, 255).astype(np.uint8))
    return out


@pytest.fixture(scope="module")
def vits() -> dinov2.DinoVisionTransformer:
    return dinov2.random_dinov2("vits14", seed=1)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory, vits) -> str:
    path = tmp_path_factory.mktemp("weights") / "dinov2_vits14_pretrain.pth"
    torch.save(vits.state_dict(), path)
    return str(path)


@pytest.fixture(autouse=True)
def empty_hub(tmp_path, monkeypatch):
    """Every test sees an empty torch hub cache and AnyLoc cache of its own."""
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch_home"))
    monkeypatch.setenv("PANOTOPO_ANYLOC_CACHE", str(tmp_path / "anyloc_cache"))


# ---------------------------------------------------------------- architecture

def test_vits14_state_dict_matches_official_names_and_shapes():
    assert shapes_of("vits14") == official_vits14_shapes()


@pytest.mark.parametrize("backbone, dim, depth", [
    ("vits14", 384, 12), ("vitb14", 768, 12), ("vitl14", 1024, 24), ("vitg14", 1536, 40)])
def test_backbone_sizes_and_registers(backbone, dim, depth):
    plain, reg = shapes_of(backbone), shapes_of(backbone + "_reg")
    assert plain["pos_embed"] == (1, 1370, dim)
    assert max(int(k.split(".")[1]) for k in plain if k.startswith("blocks.")) == depth - 1
    assert set(reg) - set(plain) == {"register_tokens"} and reg["register_tokens"] == (1, 4, dim)
    assert dinov2.get_arch(backbone + "_reg").checkpoint_name == f"dinov2_{backbone}_reg4_pretrain.pth"


def test_vitg14_uses_swiglu_with_official_hidden_size():
    s = shapes_of("vitg14")
    hidden = (int(4 * 1536 * 2 / 3) + 7) // 8 * 8
    assert hidden == 4096
    assert s["blocks.39.mlp.w12.weight"] == (2 * hidden, 1536)
    assert s["blocks.39.mlp.w3.weight"] == (1536, hidden)
    assert not any("fc1" in k for k in s)


def test_attention_equals_manual_softmax_attention(vits):
    attn = vits.blocks[0].attn
    x = torch.randn(2, 9, 384)
    heads, hd = 6, 64
    with torch.no_grad():
        q, k, v = F.linear(x, attn.qkv.weight, attn.qkv.bias).split(384, dim=-1)
        split = lambda t: t.reshape(2, 9, heads, hd).transpose(1, 2)
        w = torch.softmax(split(q) @ split(k).transpose(-1, -2) / math.sqrt(hd), dim=-1)
        manual = F.linear((w @ split(v)).transpose(1, 2).reshape(2, 9, 384), attn.proj.weight, attn.proj.bias)
        assert torch.allclose(attn(x), manual, atol=1e-5)


@pytest.mark.parametrize("backbone", ["vits14", "vits14_reg"])
def test_facets_are_thirds_of_the_qkv_output(backbone, vits):
    model = vits if backbone == "vits14" else dinov2.random_dinov2(backbone, seed=2)
    layer = 5
    block = model.blocks[layer]
    seen = {}
    pre = block.register_forward_pre_hook(lambda m, args: seen.__setitem__("input", args[0]))
    post = block.register_forward_hook(lambda m, args, out: seen.__setitem__("output", out))
    x = torch.randn(2, 3, 56, 112)
    with torch.no_grad():
        model(x)
        pre.remove(), post.remove()
        n_prefix = 1 + model.arch.registers
        assert seen["input"].shape[1] == n_prefix + 4 * 8
        tokens = F.layer_norm(seen["input"], (384,), block.norm1.weight, block.norm1.bias, eps=1e-6)
        w, b = block.attn.qkv.weight, block.attn.qkv.bias
        for i, facet in enumerate(["query", "key", "value"]):
            manual = tokens @ w[i * 384:(i + 1) * 384].T + b[i * 384:(i + 1) * 384]
            got = model.extract(x, layer, facet)
            assert got.shape == (2, 4 * 8, 384)           # CLS and registers dropped
            assert torch.allclose(got, manual[:, n_prefix:], atol=1e-4), facet
        assert torch.allclose(model.extract(x, layer, "token"), seen["output"][:, n_prefix:], atol=1e-4)
        # The facets really differ (a wrong slice would make two of them equal).
        assert not torch.allclose(model.extract(x, layer, "key"), model.extract(x, layer, "value"))


def test_registers_get_no_position_and_sit_between_cls_and_patches():
    model = dinov2.random_dinov2("vits14_reg", seed=3)
    x = torch.randn(1, 3, 28, 42)
    with torch.no_grad():
        tokens = model.prepare_tokens(x)
    assert tokens.shape == (1, 1 + 4 + 2 * 3, 384)
    assert torch.equal(tokens[0, 1:5], model.register_tokens[0])
    assert not torch.equal(tokens[0, 0], model.cls_token[0, 0])  # CLS carries its position


def test_positional_embedding_interpolation_keeps_row_and_column_layout(vits):
    model = dinov2.DinoVisionTransformer(dinov2.get_arch("vits14"))
    rows = torch.arange(37, dtype=torch.float32).repeat_interleave(37)   # value = grid row
    with torch.no_grad():
        model.pos_embed.zero_()
        model.pos_embed[0, 1:, 0] = rows
        model.pos_embed[0, 0, 0] = -5.0
        same = model.interpolate_pos_encoding(37, 37)
        pos = model.interpolate_pos_encoding(4, 8)
    assert same is model.pos_embed
    assert pos.shape == (1, 1 + 32, 384) and pos[0, 0, 0] == -5.0
    grid = pos[0, 1:, 0].reshape(4, 8)
    assert torch.allclose(grid, grid[:, :1].expand(4, 8), atol=1e-4)   # constant along a row
    assert torch.all(grid[1:, 0] > grid[:-1, 0])                         # increasing downwards



def test_the_kept_positional_embedding_follows_the_weights():
    # Inference mode keeps the last grid's embedding; weights changed in place must not be
    # served stale, and what is kept equals what would be computed afresh.
    model = dinov2.random_dinov2("vits14", seed=4)
    with torch.no_grad():
        fresh = model.interpolate_pos_encoding(4, 8).clone()
    with torch.inference_mode():
        first = model.interpolate_pos_encoding(4, 8)
        assert model.interpolate_pos_encoding(4, 8) is first and torch.equal(first, fresh)
    with torch.no_grad():
        model.pos_embed.mul_(2.0)
    with torch.inference_mode():
        assert torch.allclose(model.interpolate_pos_encoding(4, 8), 2.0 * fresh, atol=1e-6)
        assert model.interpolate_pos_encoding(2, 8).shape == (1, 1 + 16, 384)


# ---------------------------------------------------------------- checkpoints and errors

def test_missing_weights_name_the_file_and_the_option():
    with pytest.raises(InputError) as err:
        AnyLocVLAD(backbone="vits14")
    msg = str(err.value)
    assert "dinov2_vits14_pretrain.pth" in msg and "--weights" in msg and "checkpoints" in msg
    with pytest.raises(InputError, match="no such DINOv2 checkpoint"):
        AnyLocVLAD(backbone="vits14", weights="/nonexistent/dinov2_vits14_pretrain.pth")


def test_hub_cache_checkpoint_is_found(ckpt, tmp_path):
    cache = tmp_path / "torch_home" / "hub" / "checkpoints"
    cache.mkdir(parents=True)
    (cache / "dinov2_vits14_pretrain.pth").symlink_to(ckpt)
    model = AnyLocGeM(backbone="vits14", input_height=H)
    assert model.weights_path == cache / "dinov2_vits14_pretrain.pth"
    out = model.describe(iter(images(2)), 2)
    assert out.shape == (2, 384)


def test_mismatched_checkpoint_names_expected_architecture(ckpt):
    with pytest.raises(InputError) as err:
        dinov2.load_dinov2("vitb14", weights=ckpt)
    msg = str(err.value)
    assert "not a DINOv2 ViT-B/14 checkpoint" in msg and "ViT-S/14" in msg and "shape" in msg


def test_foreign_state_dict_is_rejected(tmp_path, vits):
    path = tmp_path / "other.pth"
    state = dict(vits.state_dict())
    state.pop("blocks.3.ls1.gamma")
    torch.save(state, path)
    with pytest.raises(InputError, match=r"not a DINOv2 ViT-S/14 checkpoint \(blocks.3.ls1.gamma is missing\)"):
        dinov2.load_dinov2("vits14", weights=path)


def test_truncated_checkpoint_is_a_clear_error(tmp_path, ckpt):
    data = open(ckpt, "rb").read()
    path = tmp_path / "dinov2_vits14_pretrain.pth"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="truncated"):
        dinov2.load_dinov2("vits14", weights=path)
    path.write_bytes(b"not a checkpoint at all")
    with pytest.raises(InputError, match="truncated or not a PyTorch checkpoint"):
        dinov2.load_dinov2("vits14", weights=path)


def test_official_checkpoint_loads_strictly(ckpt, vits):
    model = dinov2.load_dinov2("vits14", weights=ckpt)
    for k, v in vits.state_dict().items():
        assert torch.equal(model.state_dict()[k], v)


def test_bad_options_are_input_errors(ckpt):
    with pytest.raises(InputError, match="layers 0..11"):
        AnyLocVLAD(backbone="vits14", weights=ckpt, layer=31)
    with pytest.raises(InputError, match="facet"):
        AnyLocVLAD(backbone="vits14", weights=ckpt, facet="attention")
    with pytest.raises(InputError, match="unknown DINOv2 backbone"):
        AnyLocVLAD(backbone="vith14", weights=ckpt)


# ---------------------------------------------------------------- AnyLoc maths

def test_anyloc_vlad_hand_example_with_nonunit_centres():
    # Two 2-D centres of length 0.5 (k-means means of unit vectors are shorter than 1).
    centers = np.array([[0.5, 0.0], [0.0, 0.5]], np.float32)
    s = 1 / math.sqrt(2)
    feats = np.array([[1.0, 0.0], [s, s - 1e-3], [0.0, 1.0]], np.float32)
    feats /= np.linalg.norm(feats, axis=1, keepdims=True)
    # By hand: rows 0 and 1 go to centre 0 (cosine), row 2 to centre 1; residuals to the raw centres.
    r0 = feats[0] - centers[0] + feats[1] - centers[0]
    r1 = feats[2] - centers[1]
    expected = np.concatenate([r0 / np.linalg.norm(r0), r1 / np.linalg.norm(r1)]) / math.sqrt(2)
    assert np.allclose(anyloc_vlad(feats, centers), expected, atol=1e-6)


def test_anyloc_vlad_matches_reference_formula_on_random_data():
    rng = np.random.default_rng(4)
    feats = rng.normal(size=(200, 16)).astype(np.float32)
    feats /= np.linalg.norm(feats, axis=1, keepdims=True)
    centers = rng.normal(size=(8, 16)).astype(np.float32) * rng.uniform(0.2, 0.9, (8, 1)).astype(np.float32)
    f, c = torch.from_numpy(feats), torch.from_numpy(centers)
    labels = (F.normalize(f, dim=1) @ F.normalize(c, dim=1).T).argmax(1)
    blocks = [F.normalize((f[labels == j] - c[j]).sum(0), dim=0) for j in range(8)]
    reference = F.normalize(torch.cat(blocks), dim=0).numpy()
    assert np.allclose(anyloc_vlad(feats, centers), reference, atol=1e-5)


def test_gem_signed_cube_root_by_hand():
    feats = np.array([[1.0, -2.0], [3.0, 0.0]])
    assert np.allclose(gem(feats, 3.0), [14 ** (1 / 3), -(4 ** (1 / 3))])


def test_pca_keeps_the_angles_of_low_rank_data():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(6, 2)) @ rng.normal(size=(2, 50)) + rng.normal(size=(1, 50))
    centred = x - x.mean(0)
    cos = lambda a: (a / np.linalg.norm(a, axis=1, keepdims=True)) @ (a / np.linalg.norm(a, axis=1, keepdims=True)).T
    out = pca_project(x, 3)
    assert out.shape == (6, 3)
    assert np.allclose(cos(out), cos(centred), atol=1e-6)


def test_preprocess_keeps_the_whole_panorama_and_normalises():
    assert input_size(224) == (224, 448) and input_size(100) == (98, 196)
    rgb = np.zeros((300, 600, 3), np.uint8)
    rgb[:, :300] = 255                       # left half white
    x = preprocess(rgb, 100)
    assert x.shape == (3, 98, 196) and x.dtype == np.float32
    white = (1 - np.array([0.485, 0.456, 0.406])) / np.array([0.229, 0.224, 0.225])
    assert np.allclose(x[:, 50, 10], white, atol=1e-5)
    assert np.allclose(x[:, 50, 190], -np.array([0.485, 0.456, 0.406]) / np.array([0.229, 0.224, 0.225]), atol=1e-5)


# ---------------------------------------------------------------- descriptors end to end

def test_vlad_map_vocabulary_gives_32_x_384_unit_rows(ckpt, vits, tmp_path):
    saved = tmp_path / "c_centers.pt"
    # On the CPU: on CUDA "auto" runs a file vocabulary in bfloat16 (test_gpu_arithmetic checks that).
    model = AnyLocVLAD(backbone="vits14", weights=ckpt, input_height=H, save_vocabulary=str(saved), device="cpu")
    stages = []
    out = model.describe(iter(images(4)), 4, progress=lambda d, t, s: stages.append((d, t, s)))
    assert out.shape == (4, 32 * 384) and out.dtype == np.float32
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-5)
    assert stages[-1][0] == stages[-1][1]
    assert model.settings()["vocabulary"] == "map" and model.settings()["layer"] == 10
    # The saved map vocabulary, loaded as a file, reproduces the same descriptors (up to the
    # float16 storage of the patch features while the map vocabulary is built).
    again = AnyLocVLAD(backbone="vits14", weights=ckpt, input_height=H, vocabulary=str(saved),
                       batch_size=3, device="cpu")
    assert np.allclose(again.describe(iter(images(4)), 4), out, atol=2e-3)
    assert again.settings()["vocabulary"].startswith("c_centers.pt:")


def test_vlad_with_file_vocabulary_equals_manual_pipeline(ckpt, vits, tmp_path):
    rng = np.random.default_rng(6)
    centers = rng.normal(size=(32, 384)).astype(np.float32) * 0.6
    path = tmp_path / "c_centers.pt"
    save_vocabulary(path, centers)
    assert np.array_equal(load_vocabulary(path, 32, 384), centers)          # round trip
    assert torch.load(path, weights_only=True).shape == (32, 384)           # AnyLoc's format
    imgs = images(3)
    out = AnyLocVLAD(backbone="vits14", weights=ckpt, input_height=H, vocabulary=str(path),
                     batch_size=2, device="cpu").describe(iter(imgs), 3)
    with torch.no_grad():
        feats = F.normalize(vits.extract(torch.from_numpy(np.stack([preprocess(i, H) for i in imgs])), 10, "value"), dim=-1)
    manual = np.stack([anyloc_vlad(f.numpy(), centers) for f in feats])
    assert np.allclose(out, manual, atol=1e-5)


def test_domain_vocabulary_from_anyloc_cache_layout(ckpt, tmp_path):
    folder = tmp_path / "anyloc_cache" / "vocabulary" / "dinov2_vits14" / "l10_value_c32" / "indoor"
    folder.mkdir(parents=True)
    save_vocabulary(folder / "c_centers.pt", np.random.default_rng(7).normal(size=(32, 384)))
    model = AnyLocVLAD(backbone="vits14", weights=ckpt, vocabulary="indoor")
    assert model.settings()["vocabulary"].startswith("indoor:")
    with pytest.raises(InputError, match="l10_value_c32/urban/c_centers.pt"):
        AnyLocVLAD(backbone="vits14", weights=ckpt, vocabulary="urban")


def test_vocabulary_for_another_backbone_is_rejected(ckpt, tmp_path):
    path = tmp_path / "c_centers.pt"
    save_vocabulary(path, np.ones((32, 1536), np.float32))
    with pytest.raises(InputError, match="1536 dimensions"):
        AnyLocVLAD(backbone="vits14", weights=ckpt, vocabulary=str(path))
    path.write_bytes(b"\x00garbage")
    with pytest.raises(InputError, match="vocabulary"):
        AnyLocVLAD(backbone="vits14", weights=ckpt, vocabulary=str(path))


def test_gem_descriptor_and_pca(ckpt):
    out = AnyLocGeM(backbone="vits14", weights=ckpt, input_height=H).describe(iter(images(3)), 3)
    assert out.shape == (3, 384) and np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-5)
    small = AnyLocGeM(backbone="vits14", weights=ckpt, input_height=H, pca_dim=2)
    assert small.describe(iter(images(3)), 3).shape == (3, 2)
    assert small.settings()["pca_dim"] == 2 and small.settings()["gem_p"] == 3.0


def test_settings_change_with_everything_that_changes_the_output(ckpt):
    base = AnyLocVLAD(backbone="vits14", weights=ckpt).settings()
    for change in [{"layer": 9}, {"facet": "key"}, {"input_height": 112}, {"pca_dim": 64},
                   {"num_clusters": 16}]:
        assert AnyLocVLAD(backbone="vits14", weights=ckpt, **change).settings() != base, change
    assert base["input_size"] == [224, 448]


def test_cancel_stops_between_batches(ckpt):
    stop = threading.Event()
    stop.set()
    with pytest.raises(Cancelled):
        AnyLocVLAD(backbone="vits14", weights=ckpt, input_height=H).describe(iter(images(2)), 2, cancel=stop)


def test_device_selection():
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match="CUDA"):
            pick_device("cuda")
        assert pick_device("auto").type in ("cpu", "mps")
    assert pick_device("cpu").type == "cpu"


@pytest.mark.parametrize("backbone", ["vits14", "vits14_reg"])
def test_positional_interpolation_follows_the_official_hub_settings(backbone):
    # Official hub models: plain ones scale by (n + 0.1) / 37 without antialiasing,
    # the _reg ones resize to the exact grid with antialiasing.
    model = dinov2.random_dinov2(backbone, seed=8)
    grid = model.pos_embed[:, 1:].reshape(1, 37, 37, 384).permute(0, 3, 1, 2)
    with torch.no_grad():
        if model.arch.registers:
            ref = F.interpolate(grid, size=(4, 8), mode="bicubic", antialias=True)
        else:
            ref = F.interpolate(grid, scale_factor=(4.1 / 37, 8.1 / 37), mode="bicubic")
        got = model.interpolate_pos_encoding(4, 8)[:, 1:].reshape(1, 4, 8, 384).permute(0, 3, 1, 2)
    assert torch.allclose(got, ref, atol=1e-6)


def test_cli_map_and_describe_with_anyloc_vlad(ckpt, tmp_path):
    import cv2
    import networkx as nx

    from engine.cli import main

    video = tmp_path / "rec.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (128, 64))
    base = images(1)[0]
    for i in range(40):  # 4 s at 10 fps -> 4 sampled frames
        writer.write(np.roll(base, 3 * i, axis=1)[:, :, ::-1])
    writer.release()
    common = ["--descriptor", "anyloc-vlad", "--weights", ckpt, "--backbone", "vits14",
              "--input-height", str(H), "--no-cache", "-q"]
    npz = tmp_path / "d.npz"
    assert main(["describe", str(video), "-o", str(npz), *common]) == 0
    with np.load(npz) as z:
        d = z["descriptors"]
    assert d.shape == (4, 32 * 384) and d.dtype == np.float32
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
    out = tmp_path / "map.graphml"
    assert main(["map", str(video), "-o", str(out), *common]) == 0
    graph = nx.read_graphml(out)
    assert graph.graph["descriptor"] == "anyloc-vlad" and graph.number_of_nodes() >= 1


# ---------------------------------------------------------------- backbone from the checkpoint

def shape_only_checkpoint(path, backbone: str) -> str:
    """A checkpoint with the official keys and shapes of ``backbone`` whose tensors are one
    broadcast number each (a few kB on disk even for ViT-G/14): enough to read shapes from."""
    state = {k: torch.zeros(()).expand(shape) for k, shape in shapes_of(backbone).items()}
    torch.save(state, path)
    return str(path)


@pytest.mark.parametrize("backbone", ["vitb14", "vitl14_reg", "vitg14", "vits14_reg"])
def test_backbone_is_read_from_the_checkpoint_shapes(backbone, tmp_path):
    path = shape_only_checkpoint(tmp_path / "weights.pth", backbone)
    assert dinov2.checkpoint_arch(path) == dinov2.get_arch(backbone)
    model = AnyLocVLAD(weights=path)                 # no backbone given
    assert model.arch == dinov2.get_arch(backbone)
    assert model.layer == {"vitb14": 10, "vitl14_reg": 20, "vitg14": 31, "vits14_reg": 10}[backbone]


def test_checkpoint_without_backbone_option_describes(ckpt):
    out = AnyLocVLAD(weights=ckpt, input_height=H).describe(iter(images(2)), 2)
    assert out.shape == (2, 32 * 384)


def test_backbone_contradicting_the_checkpoint_is_one_clear_line(ckpt, tmp_path):
    with pytest.raises(InputError) as err:
        AnyLocGeM(weights=ckpt, backbone="vitg14")
    msg = str(err.value)
    assert "holds DINOv2 ViT-S/14" in msg and "ViT-G/14" in msg and "--backbone vits14" in msg
    assert "\n" not in msg
    foreign = tmp_path / "other.pth"
    torch.save({"conv.weight": torch.zeros(3, 3)}, foreign)
    with pytest.raises(InputError, match="cannot tell its backbone"):
        AnyLocVLAD(weights=str(foreign))


def test_cli_describe_without_backbone_reads_it_from_the_weights(ckpt, tmp_path):
    import cv2

    from engine.cli import main

    video = tmp_path / "rec.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (128, 64))
    for i in range(20):
        writer.write(np.roll(images(1)[0], 3 * i, axis=1)[:, :, ::-1])
    writer.release()
    npz = tmp_path / "d.npz"
    args = ["describe", str(video), "-o", str(npz), "--descriptor", "anyloc-gem", "--weights", ckpt,
            "--input-height", str(H), "--no-cache", "-q"]
    assert main(args) == 0
    with np.load(npz) as z:
        assert z["descriptors"].shape[1] == 384
    assert main(args + ["--backbone", "vitb14"]) != 0
