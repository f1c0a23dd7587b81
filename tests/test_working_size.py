"""Large frames are described from one shrunk working copy; the stored shift stays in the
source frame's columns (the .npz contract) and agrees with the full-size shift."""

from pathlib import Path

import cv2
import numpy as np

from engine.frames import Frame
from engine import descriptors
from engine.pipeline import WORK_WIDTH, DescribeSettings, describe_frames, work_width, working_copy
from engine.shift import apply_shift, canonical_shift

PANO = Path(__file__).parent / "data" / "examplepano_1024.jpg"


def test_a_4k_frame_keeps_its_shift_in_source_columns():
    small = cv2.imread(str(PANO))[:, :, ::-1]
    big = cv2.resize(small, (4096, 2048), interpolation=cv2.INTER_CUBIC)
    big = apply_shift(big, 1234)                         # some heading
    assert working_copy(big).shape[1] == WORK_WIDTH
    full = canonical_shift(big)
    d = describe_frames([Frame(0, 0.0, big)], 1, DescribeSettings(options={"input_height": 64}))
    assert d.meta["frame_width"] == 4096
    err = (int(d.shifts[0]) - full + 2048) % 4096 - 2048
    assert abs(err) <= 4                                 # a few source columns (0.35 degree)


def test_frames_up_to_the_working_width_are_used_as_they_are():
    frame = np.zeros((256, 512, 3), np.uint8)
    assert working_copy(frame) is frame


def test_a_frame_delivered_shrunk_keeps_its_shift_in_the_recordings_columns():
    big = cv2.resize(cv2.imread(str(PANO))[:, :, ::-1], (4096, 2048), interpolation=cv2.INTER_CUBIC)
    big = apply_shift(big, 777)
    small = working_copy(big)
    settings = DescribeSettings(options={"input_height": 64})
    whole = describe_frames([Frame(0, 0.0, big)], 1, settings)
    shrunk = describe_frames([Frame(0, 0.0, small, source_width=4096)], 1, settings)
    assert shrunk.meta["frame_width"] == 4096
    assert abs((int(shrunk.shifts[0]) - int(whole.shifts[0]) + 2048) % 4096 - 2048) <= 4


def test_a_network_wider_than_the_working_copy_is_not_fed_an_upsampled_frame():
    wide = descriptors.get("effnet-vlad", input_height=WORK_WIDTH)      # 2 * WORK_WIDTH columns in
    assert work_width(wide) == 2 * WORK_WIDTH
    assert work_width(descriptors.get("effnet-vlad")) == WORK_WIDTH
