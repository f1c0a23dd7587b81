"""Every numeric limit on what panotopo accepts, in one place (README "Limits").

Each limit exists so that a nonsense or hostile input gets one clear line BEFORE
anything large is decoded or allocated (issue 16, findings 10, 11, 14), instead of a
traceback, a MemoryError, a segfault or a silently meaningless result.
"""

from __future__ import annotations

# --- frames --------------------------------------------------------------------------
# Largest frame accepted: 16384 x 8192 (134 Mpixel, 400 MB as RGB). The biggest 360-degree
# cameras on sale record 11K (11008 x 5504, Insta360 Titan) or 12K stitched stills; 16K
# leaves room above them while one decoded frame still fits comfortably in memory
# (issue 16 found 30000 x 15000 and 48000 x 24000 frames accepted: 1.3 GB and 3.5 GB each).
MAX_FRAME_WIDTH = 16384
MAX_FRAME_HEIGHT = 8192
# Smallest frame accepted: 32 x 16. The panorama shift and the column signatures need
# rows and columns to take gradients over; a 2 x 1 "panorama" crashed the shift (issue 16).
MIN_FRAME_WIDTH = 32
MIN_FRAME_HEIGHT = 16

# --- sampling --------------------------------------------------------------------------
# --interval: 0 takes every frame; otherwise between 1 ms (faster than any camera's frame
# period, 1e-300 made the sampler's arange overflow) and one day (a longer gap between
# samples is surely a typo: no recording is mapped with one node a day).
MIN_INTERVAL_S = 0.001
MAX_INTERVAL_S = 86400.0

# --- descriptor options ----------------------------------------------------------------
# Descriptor input height: the models are run on (2h x h) images; 2048 (4096 x 2048 input)
# is already past what the backbones were trained on (224-518 px) and needs GBs of
# activations per image; 16000 ran out of memory (issue 16).
MIN_INPUT_HEIGHT = 32
MAX_INPUT_HEIGHT = 2048
MAX_BATCH_SIZE = 1024
MAX_PCA_DIM = 65536

# --- map parameters --------------------------------------------------------------------
# Temporal neighbours and windows are counted in nodes; more than a million nodes is
# beyond MAX_DENSE_NODES for every method anyway, so larger values are typos.
MAX_NODE_COUNT_PARAM = 1_000_000
# Cosine similarities lie in [-1, 1]; a threshold outside can never (or always) match.
MIN_COSINE = -1.0
MAX_COSINE = 1.0
# Same-place distance for evaluation, metres: positive and below 10 km.
MAX_DIST_TH_M = 10_000.0

# Ground-truth poses must cover at least half of the map's node stamps (the rest would be
# clamped to the first or last pose): less means another clock, and meaningless metrics.
MIN_POSES_COVERAGE = 0.5

# --- memory ------------------------------------------------------------------------------
# Methods that hold whole (nodes x nodes) matrices (``verified``: similarities, z-scores,
# column z-scores, support, all float32, about 5 live at once; the similarity picture of a
# plot) refuse above this many nodes: 20,000^2 x 4 B = 1.6 GB per matrix, ~8 GB at the
# peak, within a 16 GB laptop. Issue 16 measured 50,000 nodes segfaulting under
# ``verified`` and 200,000 asking for 149 GiB.
MAX_DENSE_NODES = 20_000
# Descriptors kept in memory while describing (vectors, column signatures, colours and the
# model's own per-frame features): refused before decoding when the estimate exceeds this.
MAX_DESCRIBE_BYTES = 12 * 2**30

# --- files read ------------------------------------------------------------------------
# A descriptors .npz: each member's declared uncompressed size, and their sum, must stay
# below these (a zip bomb of 37 GiB was accepted, then died of MemoryError). 200,000 frames
# of effnet-vlad (3584 float32) are 2.9 GB; the optional column signatures add as much.
MAX_NPZ_MEMBER_BYTES = 8 * 2**30
MAX_NPZ_TOTAL_BYTES = 16 * 2**30
# The JSON ``meta`` member of a .npz and a session file: text, never large.
MAX_JSON_BYTES = 64 * 2**20
# Demo: the synthetic panorama's width (height = width / 2).
MIN_DEMO_WIDTH = 64
MAX_DEMO_WIDTH = 4096
MAX_SEED = 2**32 - 1


def table() -> list[tuple[str, str]]:
    """(name, value) of every limit, for the README and ``--help`` texts."""
    return [
        ("frame size", f"{MIN_FRAME_WIDTH}x{MIN_FRAME_HEIGHT} to {MAX_FRAME_WIDTH}x{MAX_FRAME_HEIGHT} pixels"),
        ("--interval", f"0 (every frame) or {MIN_INTERVAL_S} to {MAX_INTERVAL_S:g} s"),
        ("--input-height", f"{MIN_INPUT_HEIGHT} to {MAX_INPUT_HEIGHT} pixels"),
        ("--batch-size", f"1 to {MAX_BATCH_SIZE}"),
        ("--node-sim-th / --loop-sim-th", f"{MIN_COSINE} to {MAX_COSINE} (cosine)"),
        ("--window-size", f"1 to {MAX_NODE_COUNT_PARAM:,}"),
        ("--count-th / --neighbor-node-num", f"0 to {MAX_NODE_COUNT_PARAM:,}"),
        ("--dist-th", f"above 0, up to {MAX_DIST_TH_M:g} m"),
        ("nodes in the plot's similarity picture", f"{MAX_DENSE_NODES:,}"),
        ("descriptors in memory while describing", f"{MAX_DESCRIBE_BYTES / 2**30:g} GiB"),
        (".npz member / whole file, uncompressed", f"{MAX_NPZ_MEMBER_BYTES / 2**30:g} / {MAX_NPZ_TOTAL_BYTES / 2**30:g} GiB"),
        ("ground-truth poses", f"at least 2, covering {MIN_POSES_COVERAGE:.0%} of the node stamps"),
        ("demo --width", f"{MIN_DEMO_WIDTH} to {MAX_DEMO_WIDTH}"),
        ("demo --seed", f"0 to {MAX_SEED}"),
    ]
