"""The frame checks' repeat digest: every byte counts, equal bytes give equal digests, the arithmetic is the
documented one (an independent pure-Python sum), and no single-bit change goes unseen."""

import numpy as np
import pytest

from pectoral_gym.hardware.vision.framecheck import FrameCheck, _digest_keys, frame_digest
from pectoral_gym.hardware.vision.frames import Frame


def _by_hand(data: bytes) -> tuple[int, int, bytes]:
    """The docstring's definition, in Python integers (no numpy arithmetic)."""
    whole, shifted = len(data) // 8, max(len(data) - 4, 0) // 8
    keys, shifted_keys = (k.tolist() for k in _digest_keys(max(whole, 1)))
    h1 = sum(int.from_bytes(data[8 * j : 8 * j + 8], "little") * keys[j] for j in range(whole)) % 2**64
    h2 = sum(int.from_bytes(data[4 + 8 * j : 12 + 8 * j], "little") * shifted_keys[j] for j in range(shifted)) % 2**64
    return h1, h2, data[-8:]


@pytest.mark.parametrize("shape", [(5, 7, 3), (4, 4, 3), (1, 1, 3), (36, 64, 3)])
def test_digest_is_the_documented_sum(shape):
    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    assert frame_digest(image) == _by_hand(image.tobytes())


@pytest.mark.parametrize("size", [*range(0, 41), 1003, 1004, 1007])
def test_digest_is_the_documented_sum_for_every_tail(size):
    """Every length modulo 8: the shifted words end inside the whole ones, or reach into the ragged tail."""
    data = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
    data.setflags(write=False)  # a read-only frame (a camera's buffer) too
    assert frame_digest(data) == _by_hand(data.tobytes())


def test_every_single_bit_flip_changes_the_digest():
    image = np.random.default_rng(2).integers(0, 256, (5, 7, 3), dtype=np.uint8)  # 105 bytes: a ragged tail
    base = frame_digest(image)
    flat = image.reshape(-1)
    for position in range(flat.size):
        for bit in range(8):
            flipped = flat.copy()
            flipped[position] ^= np.uint8(1 << bit)
            assert frame_digest(flipped.reshape(image.shape)) != base, (position, bit)


def test_equal_bytes_equal_digest_whatever_the_layout():
    image = np.random.default_rng(3).integers(0, 256, (36, 64, 3), dtype=np.uint8)
    strided = np.asfortranarray(image)
    assert not strided.flags.c_contiguous
    assert frame_digest(strided) == frame_digest(image.copy())


def test_a_repeat_among_the_last_frames_is_frozen_and_a_one_level_change_is_not():
    rng = np.random.default_rng(4)
    frames = [rng.integers(0, 256, (36, 64, 3), dtype=np.uint8) for _ in range(3)]
    nudged = frames[0].copy()
    nudged[20, 40, 1] ^= 1  # one grey level in one channel of one pixel
    check = FrameCheck(0.05, 1.0, history=30, min_change=0.0)
    verdicts = [check.check(Frame(image, 1.0 + i / 30), 1.0 + i / 30)
                for i, image in enumerate([*frames, nudged, frames[1].copy()])]
    assert verdicts == ["", "", "", "", "frozen_frame"]


def test_the_kernel_is_ready_before_the_first_frame_check():
    """A frame check built has its digest kernel compiled or loaded for any frame (none mid-episode, in a poll)."""
    import subprocess
    import sys

    code = """
import numpy as np
from pectoral_gym.hardware.vision import framecheck
framecheck.FrameCheck(0.05, 1.0)
ready = len(framecheck._multilinear.signatures)
frame = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
framecheck.frame_digest(frame)
frame.setflags(write=False)
framecheck.frame_digest(frame)
print(ready, len(framecheck._multilinear.signatures))
"""
    ready, after = map(int, subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout.split())
    assert ready >= 1 and after == ready
