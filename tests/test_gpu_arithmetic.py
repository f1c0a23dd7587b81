"""The device path's arithmetic, checked on the CPU: batched torch VLAD equals the numpy
reference, on-device preprocessing resizes as documented, precision choices, the map
vocabulary in bounded host memory, and the stand-ins for CPU/GPU agreement (float32
perturbations of a GPU's size; bfloat16 autocast on the CPU)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from engine.descriptors import mapvocab
from engine.descriptors.accel import compute, resize, resolve_precision, shrink_on_host, to_network_input, upload
from engine.descriptors.anyloc import anyloc_vlad
from engine.descriptors.efficientnet import EfficientNetVLAD, sector_vlad, sector_weights
from engine.descriptors.vlad import kmeans_cosine, vlad
from engine.descriptors.vlad_torch import kmeans_cosine_torch, kmeans_on, sector_vlad_batch, vlad_batch
from engine.errors import InputError


def unit_rows(rng, shape) -> np.ndarray:
    x = rng.normal(size=shape).astype(np.float32)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    from engine.synth.recording import make_recording

    return list(make_recording("crossing", look="outdoor", seed=0, width=256, height=128,
                               fps=1.0, max_frames=8).frames)


def test_torch_vlad_equals_numpy_vlad_for_unit_and_anyloc_centres():
    rng = np.random.default_rng(0)
    feats = unit_rows(rng, (3, 200, 16))
    unit = unit_rows(rng, (8, 16))
    short = unit * rng.uniform(0.2, 0.9, (8, 1)).astype(np.float32)      # AnyLoc's k-means means
    got_unit = vlad_batch(torch.from_numpy(feats), torch.from_numpy(unit)).numpy()
    got_short = vlad_batch(torch.from_numpy(feats), torch.from_numpy(short)).numpy()
    for i in range(3):
        assert np.allclose(got_unit[i], vlad(feats[i], unit), atol=1e-6)
        assert np.allclose(got_short[i], anyloc_vlad(feats[i], short), atol=1e-6)


def test_torch_sector_vlad_equals_numpy_sector_vlad():
    rng = np.random.default_rng(1)
    width, rows, sectors = 16, 4, 4
    feats = unit_rows(rng, (2, width * rows, 12))
    centres = unit_rows(rng, (6, 12))
    w = sector_weights(width, sectors)[:, np.arange(width * rows) % width]
    got = sector_vlad_batch(torch.from_numpy(feats), torch.from_numpy(centres), torch.from_numpy(w), 0.5).numpy()
    for i in range(2):
        assert np.allclose(got[i], sector_vlad(feats[i], centres, width, sectors), atol=1e-6)


def test_vlad_stays_float32_under_bfloat16_autocast():
    rng = np.random.default_rng(2)
    feats, centres = torch.from_numpy(unit_rows(rng, (2, 100, 16))), torch.from_numpy(unit_rows(rng, (4, 16)))
    with compute(torch.device("cpu"), torch.bfloat16):
        got = vlad_batch(feats, centres)
    assert got.dtype == torch.float32
    assert torch.allclose(got, vlad_batch(feats, centres), atol=1e-6)


def test_network_input_averages_boxes_when_shrinking_and_normalises():
    img = np.zeros((4, 8, 3), np.uint8)
    img[:2, :2] = [255, 0, 0]                 # one 2x2 red box -> one red pixel at half size
    img[2:, 2:4] = [0, 255, 0]
    x = to_network_input([img], (2, 4), (2, 4), torch.device("cpu"), "test",
                         mean=(0, 0, 0), std=(1, 1, 1)).numpy()[0]
    assert x.shape == (3, 2, 4)
    assert np.allclose(x[:, 0, 0], [1, 0, 0]) and np.allclose(x[:, 1, 1], [0, 1, 0])
    assert np.allclose(x[:, 0, 1:], 0) and np.allclose(x[:, 1, 0], 0)
    with pytest.raises(InputError, match="expected an H x W x 3 RGB image"):
        to_network_input([np.zeros((4, 8), np.uint8)], (2, 4), (2, 4), torch.device("cpu"), "test")


def test_frames_of_mixed_sizes_are_each_resized():
    a = np.full((64, 128, 3), 200, np.uint8)
    b = np.full((32, 64, 3), 200, np.uint8)
    x = to_network_input([a, b, a], (16, 32), (14, 28), torch.device("cpu"), "test")
    assert x.shape == (3, 3, 14, 28) and torch.allclose(x[0], x[1], atol=1e-5) and torch.allclose(x[0], x[2])


def test_the_cpus_host_shrink_gives_the_devices_input():
    """On the CPU whole-factor shrinks run in OpenCV on the host; a GPU pools on the device
    with torch. Both must hand the network the same numbers (the CPU/GPU agreement)."""
    rng = np.random.default_rng(3)
    for shape, size in (((512, 1024, 3), (128, 256)), ((96, 192, 3), (32, 48)), ((128, 256, 3), (128, 256))):
        imgs = [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(3)]
        host = shrink_on_host(imgs, size)
        device = resize(torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2).float(), size)
        assert host is not None and np.abs(host.transpose(0, 3, 1, 2) - device.numpy()).max() < 1e-3
    odd = [rng.integers(0, 256, (100, 200, 3), dtype=np.uint8)]
    assert shrink_on_host(odd, (32, 64)) is None      # not whole factors: left to torch
    x = to_network_input(odd, (32, 64), (32, 64), torch.device("cpu"), "test")
    assert x.shape == (1, 3, 32, 64)


def test_precision_choices():
    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    assert resolve_precision("auto", cpu) is None
    assert resolve_precision("float32", cuda) is None
    assert resolve_precision("auto", cuda, map_vocabulary=True) is None   # reproducible vocabulary
    assert resolve_precision("bfloat16", cpu) == torch.bfloat16
    with pytest.raises(InputError, match="unknown precision"):
        resolve_precision("int8", cpu)


def test_float32_noise_of_a_gpus_size_leaves_the_map_vocabulary_unchanged():
    # Clustered features, and the same features with relative noise of 1e-6 (float32 results of
    # another device/reduction order): the float64 k-means gives the same centres.
    rng = np.random.default_rng(3)
    centres = unit_rows(rng, (32, 64))
    feats = centres[rng.integers(0, 32, 5000)] + 0.1 * rng.normal(size=(5000, 64)).astype(np.float32)
    noisy = (feats * (1 + 1e-6 * rng.normal(size=feats.shape))).astype(np.float32)
    a, b = kmeans_cosine(feats, 32, seed=0), kmeans_cosine(noisy, 32, seed=0)
    assert np.min(np.sum(a * b, axis=1)) > 0.99999


def test_bfloat16_autocast_keeps_effnet_descriptors_close_with_a_fixed_vocabulary(frames):
    ref = EfficientNetVLAD(precision="float32", input_height=64, vocabulary_size=16)
    base = ref.describe(iter(frames), len(frames))
    low = EfficientNetVLAD(precision="bfloat16", input_height=64,
                           vocabulary=ref.vocabulary).describe(iter(frames), len(frames))
    cos = np.sum(base * low, axis=1)
    assert np.median(cos) > 0.99 and cos.min() > 0.95
    assert EfficientNetVLAD(precision="bfloat16").settings() != ref.settings()


def test_map_vocabulary_memory_is_bounded_and_later_frames_stream(frames, monkeypatch):
    # A budget of about three frames' features: the vocabulary comes from the first frames,
    # the buffer is never larger than budget + one batch, later frames are pooled as they come.
    model = EfficientNetVLAD(batch_size=2, input_height=64, vocabulary_size=16)
    per_frame = 4 * 8 * 112 * 2                        # positions x channels x float16
    seen = []
    real_build = model.build_vocabulary
    monkeypatch.setattr(model, "build_vocabulary", lambda parts: seen.append(sum(p.nbytes for p in parts)) or real_build(parts))
    monkeypatch.setattr(mapvocab, "BUDGET_BYTES", 3 * per_frame)
    out = model.describe(iter(frames), len(frames))
    assert len(seen) == 1 and seen[0] <= 3 * per_frame + 2 * per_frame
    assert out.shape == (len(frames), 16 * 112) and np.allclose(np.linalg.norm(out, axis=1), 1, atol=1e-5)
    again = EfficientNetVLAD(input_height=64, vocabulary=model.vocabulary).describe(iter(frames), len(frames))
    assert np.allclose(out, again, atol=2e-3)          # float16 buffer vs float32 stream


def test_sample_rows_is_the_seeded_uniform_sample_of_all_rows():
    rng = np.random.default_rng(4)
    parts = [rng.normal(size=(n, 3)).astype(np.float16) for n in (5, 7, 4)]
    whole = np.concatenate(parts).astype(np.float32)
    pick = np.sort(np.random.default_rng(9).choice(16, 6, replace=False))
    assert np.array_equal(mapvocab.sample_rows(parts, 6, seed=9), whole[pick])
    assert np.array_equal(mapvocab.sample_rows(parts, 100, seed=9), whole)


# ---- the map vocabulary's k-means on the device (vlad_torch.kmeans_cosine_torch), checked on the CPU

def clustered(rng, n: int, dim: int, groups: int) -> np.ndarray:
    centres = unit_rows(rng, (groups, dim))
    return centres[rng.integers(0, groups, n)] + 0.3 * rng.normal(size=(n, dim)).astype(np.float32)


def test_torch_kmeans_gives_the_numpy_centres():
    rng = np.random.default_rng(5)
    feats = clustered(rng, 4000, 48, 40)
    ref = kmeans_cosine(feats, 32, seed=2)
    got = kmeans_cosine_torch(feats, 32, torch.device("cpu"), seed=2, chunk=999)   # chunks need not divide
    assert np.allclose(got, ref, atol=1e-6)


def test_torch_kmeans_reseeds_empty_clusters_as_numpy_does():
    # Ten distinct rows repeated: twelve clusters cannot all keep members, so empty ones are
    # re-seeded with the worst-represented rows on both sides.
    rng = np.random.default_rng(6)
    feats = np.repeat(unit_rows(rng, (10, 8)), 30, axis=0)
    ref = kmeans_cosine(feats, 12, seed=0)
    got = kmeans_cosine_torch(feats, 12, torch.device("cpu"), seed=0)
    assert np.allclose(got, ref, atol=1e-6)


def test_kmeans_on_the_cpu_is_the_numpy_reference():
    feats = clustered(np.random.default_rng(7), 500, 16, 8)
    assert np.array_equal(kmeans_on(torch.device("cpu"), feats, 8, seed=1), kmeans_cosine(feats, 8, seed=1))


def test_pooled_rows_are_the_same_however_often_they_are_copied_to_the_host(monkeypatch):
    rng = np.random.default_rng(8)
    batches = [torch.from_numpy(unit_rows(rng, (2, 30, 8))) for _ in range(5)]
    centres = unit_rows(rng, (4, 8))
    monkeypatch.setattr(mapvocab, "ROWS_ON_DEVICE_BYTES", 1)          # a copy per batch
    each, _ = mapvocab.pool_recording(iter(batches), vlad_batch, torch.device("cpu"), centers=centres)
    monkeypatch.setattr(mapvocab, "ROWS_ON_DEVICE_BYTES", 1 << 30)    # one copy at the end
    once, _ = mapvocab.pool_recording(iter(batches), vlad_batch, torch.device("cpu"), centers=centres)
    assert each.shape == (10, 32) and np.array_equal(each, once)


def test_upload_stacks_frames_as_they_are():
    rng = np.random.default_rng(9)
    frames = [rng.integers(0, 256, (4, 6, 3), dtype=np.uint8) for _ in range(3)]
    assert np.array_equal(upload(frames, torch.device("cpu")).numpy(), np.stack(frames))
    floats = [f.astype(np.float32) for f in frames]
    assert np.array_equal(upload(floats, torch.device("cpu")).numpy(), np.stack(floats))


# ---- on a CUDA device only (CI has none; the tests above check the same arithmetic on the CPU)

cuda_only = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


@cuda_only
def test_cuda_kmeans_gives_the_cpus_centres():
    feats = clustered(np.random.default_rng(10), 20000, 256, 64)
    ref = kmeans_cosine(feats, 32, seed=0)
    got = kmeans_on(torch.device("cuda"), feats, 32, seed=0)
    assert np.allclose(got, ref, atol=1e-5)


@cuda_only
def test_cuda_float32_describe_agrees_with_the_cpu(frames, tmp_path):
    from engine.descriptors import dinov2
    from engine.descriptors.anyloc import AnyLocVLAD

    weights = tmp_path / "dinov2_vits14_pretrain.pth"
    torch.save(dinov2.random_dinov2("vits14", seed=1).state_dict(), weights)
    rows = {dev: AnyLocVLAD(weights=str(weights), input_height=112, device=dev, precision="float32",
                            num_clusters=8).describe(iter(frames), len(frames)) for dev in ("cpu", "cuda")}
    cos = np.sum(rows["cpu"] * rows["cuda"], axis=1)
    assert cos.min() > 0.9999
    effnet = {dev: EfficientNetVLAD(input_height=64, vocabulary_size=16, device=dev, precision="float32")
              .describe(iter(frames), len(frames)) for dev in ("cpu", "cuda")}
    assert np.sum(effnet["cpu"] * effnet["cuda"], axis=1).min() > 0.9999
