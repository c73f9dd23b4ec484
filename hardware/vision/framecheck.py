"""Which camera frames count as a new sighting of the fish: a sane clock and new image content.

A frame source may hand out frames that look new but are not: stamped by another host's clock (far in
the future or the past), with a NaN or infinite stamp, stamped earlier than the last one, or a frozen
camera re-delivering old images with fresh stamps. :class:`FrameCheck` rejects each with a reason; a
rejected frame counts as "fish not seen", so the tracking timeout stops the fins.

Liveness rests on one physical fact: a live image sensor never delivers the same pixels twice. Its
noise alone (photon shot noise, read noise) makes two exposures of a still scene differ in every
region of more than a few pixels. So:

* **whole image**: a bit-identical repeat of *any* of the last ``history`` images is frozen (a driver
  cycling its last few buffers repeats an image within as many frames). The digest (:func:`frame_digest`)
  is a deterministic function of every byte, so a repeat always shares its predecessor's digest; two
  different images share one only by a collision, which stops a live fish (a false, safe stop) and can
  never hide a repeat. It need not resist a forger: a source that alters bytes to pass is the noisy
  freeze, which only the physics can catch (``pectoral_gym.hardware.safety.liveness``). So it is a fast
  keyed sum (two 64-bit multilinear hashes, see :func:`frame_digest` for their collision bound) rather
  than a cryptographic hash.
* **fish region** (``region``, a pixel box around the fish's last sighting, from the caller): a repeat
  of that region's content among the recent frames is frozen, even when the rest of the image changes
  (a frozen sensor under a camera's running clock overlay). "Repeat" means a mean absolute difference
  below ``min_change`` grey levels over the overlapping part of the two boxes. Two exposures of a still
  scene with independent Gaussian noise of standard deviation sigma differ by ``2 sigma / sqrt(pi)``
  = 1.13 sigma on average; photon shot noise alone at mid-grey is about 1.8 grey levels for a sensor
  of 10 000 e- full well digitised to 8 bits (sqrt(5000) e- at ~39 e-/level), more for smaller pixels.
  The default ``min_change`` of 0.5 grey levels is a quarter of that: a live region passes with a wide
  margin (the emulator's sigma = 2 gives 2.3), a frozen one, re-encoded losslessly or by a block codec
  (JPEG) whose blocks did not change, gives 0. A camera with temporal noise reduction can make a still
  scene nearly noise-free: switch that off, or set ``min_change=0`` (bit-identical repeats only).
"""

from __future__ import annotations

import collections
import functools
import math

import cv2
import numpy as np

from pectoral_gym.hardware.vision.frames import Frame
from pectoral_gym.model.jit import njit

__all__ = ["FrameCheck", "FRAME_REASONS", "Region", "frame_digest"]

FRAME_REASONS = ("bad_image", "bad_timestamp", "timestamp_backwards", "timestamp_future", "frame_too_old",
                 "frozen_frame")

Region = tuple[int, int, int, int]  # (row0, row1, col0, col1) pixels, end exclusive

_MIN_OVERLAP = 0.5  # two regions are compared when they share at least this much of the smaller one


_DIGEST_SEED = 0x0D16E57  # fixes the digest's keys: the same bytes give the same digest in every process


@functools.lru_cache(maxsize=4)
def _digest_keys(words: int) -> tuple[np.ndarray, np.ndarray]:
    """Two arrays of ``words`` uniform 64-bit keys, drawn once per frame size from a fixed seed."""
    rng = np.random.default_rng(_DIGEST_SEED)
    keys = rng.integers(0, 2**64, size=(2, words), dtype=np.uint64, endpoint=False)
    keys.setflags(write=False)
    return keys[0], keys[1]


def frame_digest(image: np.ndarray) -> tuple[int, int, bytes]:
    """A digest of every byte of ``image`` (C order): equal bytes, equal digest; different ones almost never.

    Two multilinear hashes modulo 2^64 of the bytes read as little-endian 64-bit words, with keys ``k``
    drawn once from a fixed seed: ``h1 = sum(k1[j] w[j])`` over the words from byte 0 and
    ``h2 = sum(k2[j] w'[j])`` over the words from byte 4, plus the last 8 bytes as they are.

    Collision bound (over the draw of the keys, which no camera's frames depend on): if two images of
    the same size differ, some differing byte sits in the low half (bits 0-31) of a word of one of the
    two word sequences, which that sequence covers (or it is among the last 8 bytes, compared as they
    are). That word's difference ``d`` is then non-zero with its lowest set bit ``b <= 31``, and
    ``k d`` for a uniform 64-bit ``k`` is uniform over the multiples of ``2^b``: the hash's sum hits
    the other image's value with probability ``2^(b - 64) <= 2^-33``. Two frames of a live sensor
    differ by noise in the lowest bit of bytes at every position (``b = 0`` in both hashes, whose keys
    are independent): ``2^-128``.

    Args:
        image: Any array; its bytes in C order are digested (a non-contiguous one is copied first).

    Returns:
        ``(h1, h2, tail)``, hashable and comparable.
    """
    flat = np.ascontiguousarray(image).reshape(-1).view(np.uint8)
    size = flat.size
    whole, shifted = size // 8, max(size - 4, 0) // 8
    if not whole:
        return 0, 0, flat[-8:].tobytes()
    keys, shifted_keys = _digest_keys(whole)
    # the shifted words inside the whole ones in one pass over the image; a last one that reaches into the
    # ragged tail (4 to 7 bytes past the whole words) is added here, in Python's integers modulo 2^64
    inside = min(shifted, whole - 1)
    h1, h2 = _multilinear(flat[: 8 * whole].view("<u8"), keys, shifted_keys, inside)
    h1, h2 = int(h1), int(h2)
    if shifted > inside:
        last = int.from_bytes(flat[4 + 8 * inside : 12 + 8 * inside].tobytes(), "little")
        h2 = (h2 + int(shifted_keys[inside]) * last) % 2**64
    return h1, h2, flat[-8:].tobytes()


@njit
def _multilinear(words: np.ndarray, keys: np.ndarray, shifted_keys: np.ndarray, shifted: int) -> tuple[int, int]:
    """``sum(keys[j] words[j])`` over all words and ``sum(shifted_keys[j] w'[j])`` over ``j < shifted``, mod 2^64.

    ``w'[j]`` is the little-endian word at byte ``8 j + 4``: the high half of ``words[j]`` and the low half of
    ``words[j + 1]`` (``shifted`` < the number of words). Unsigned 64-bit products and sums wrap modulo 2^64.
    """
    h1 = np.uint64(0)
    h2 = np.uint64(0)
    for j in range(words.shape[0]):
        h1 += keys[j] * words[j]
    half = np.uint64(32)
    for j in range(shifted):
        h2 += shifted_keys[j] * ((words[j] >> half) | (words[j + 1] << half))
    return h1, h2


def _region(region: Region, shape: tuple[int, ...]) -> Region | None:
    """``region`` clipped to an image of ``shape``; ``None`` if nothing of it is inside."""
    try:
        row0, row1, col0, col1 = (int(v) for v in region)
    except (TypeError, ValueError):
        raise ValueError(f"region must be 4 integers (row0, row1, col0, col1), got {region!r}") from None
    if row1 <= row0 or col1 <= col0:
        raise ValueError(f"region must have row0 < row1 and col0 < col1, got {region!r}")
    row0, row1 = max(row0, 0), min(row1, shape[0])
    col0, col1 = max(col0, 0), min(col1, shape[1])
    return (row0, row1, col0, col1) if row1 > row0 and col1 > col0 else None


@functools.lru_cache(maxsize=1)
def _warm_up() -> None:
    """Compile (or load from numba's cache) the digest's kernel now, not inside a supervisor's first frame check.

    With the argument types of any frame: a writable image and a read-only one (a camera's own buffer).
    """
    image = np.zeros((2, 4, 3), dtype=np.uint8)
    frame_digest(image)
    image.setflags(write=False)
    frame_digest(image)


class FrameCheck:
    """Classify frames on arrival.

    Args:
        max_lead: A stamp more than this ahead of ``now`` is rejected (``timestamp_future``) [s].
        max_age: A stamp more than this behind ``now`` is rejected (``frame_too_old``) [s].
        history: How many recent images (digests and fish regions) a new one is compared with [frames].
        min_change: A fish region whose mean absolute difference from a recent one's is below this is
            a repeat [grey levels, 0-255]; 0 keeps bit-identical repeats only.

    Attributes:
        last_timestamp: Stamp of the last frame that passed the clock checks.
        rejected: Count per reason.
        last_change: Smallest mean absolute difference of the last checked fish region from the recent
            ones [grey levels] (``nan`` when there was no region or nothing to compare).
    """

    def __init__(self, max_lead: float, max_age: float, history: int = 30, min_change: float = 0.5):
        if not (max_lead >= 0 and max_age > 0):
            raise ValueError(f"need max_lead >= 0 and max_age > 0, got {max_lead!r}, {max_age!r}")
        if int(history) != history or history < 1:
            raise ValueError(f"history must be an integer >= 1, got {history!r}")
        if not (math.isfinite(min_change) and 0 <= min_change < 255):
            raise ValueError(f"min_change must be in [0, 255) grey levels, got {min_change!r}")
        self.max_lead, self.max_age = float(max_lead), float(max_age)
        self.min_change = float(min_change)
        self.last_timestamp: float | None = None
        self.last_change = math.nan
        self._digests: collections.deque[tuple[int, int, bytes]] = collections.deque(maxlen=int(history))
        self._regions: collections.deque[tuple[Region, np.ndarray]] = collections.deque(maxlen=int(history))
        self.rejected = dict.fromkeys(FRAME_REASONS, 0)
        _warm_up()

    def reset(self) -> None:
        """Forget the last stamp (a new episode, or a camera that was re-opened).

        The image history is kept: a live camera never repeats an image, so an image from before the
        reset coming back after it is as frozen as any other repeat.
        """
        self.last_timestamp = None

    def check(self, frame: Frame, now: float, region: Region | None = None) -> str:
        """``""`` if ``frame`` is a new sighting at ``now`` (same clock as its stamp) [s], else the reason.

        Args:
            frame: The frame to classify.
            now: Current time on the frames' clock [s].
            region: Optional pixel box ``(row0, row1, col0, col1)``, end exclusive, around the fish's
                last sighting (``pectoral_gym.hardware.vision.tracker.TrackResult.box``); clipped to the image.

        Raises:
            ValueError: ``region`` is not four integers with ``row0 < row1`` and ``col0 < col1``.
        """
        box = None if region is None or not hasattr(frame.image, "shape") else _region(region, frame.image.shape)
        reason = self._reason(frame, now, box)
        if reason:
            self.rejected[reason] += 1
        return reason

    def _reason(self, frame: Frame, now: float, box: Region | None) -> str:
        image = frame.image
        if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            return "bad_image"
        try:
            t = float(frame.timestamp)
        except (TypeError, ValueError):
            return "bad_timestamp"
        if not math.isfinite(t):
            return "bad_timestamp"
        if self.last_timestamp is not None and t <= self.last_timestamp:
            return "timestamp_backwards"
        if t > now + self.max_lead:
            return "timestamp_future"
        if t < now - self.max_age:
            return "frame_too_old"
        self.last_timestamp = t  # a frozen frame still moves the clock on: its stamp was sane
        digest = frame_digest(image)
        frozen = digest in self._digests
        self._digests.append(digest)
        self.last_change = math.nan
        if box is not None:
            frozen = self._region_repeats(image, box) or frozen
        return "frozen_frame" if frozen else ""

    def _region_repeats(self, image: np.ndarray, box: Region) -> bool:
        """Compare the fish region with the recent ones it overlaps; remember it (a copy)."""
        row0, row1, col0, col1 = box
        smallest = math.inf
        for (r0, r1, c0, c1), crop in self._regions:
            top, bottom, left, right = max(row0, r0), min(row1, r1), max(col0, c0), min(col1, c1)
            if bottom <= top or right <= left:
                continue
            smaller = min((row1 - row0) * (col1 - col0), crop.shape[0] * crop.shape[1])
            if (bottom - top) * (right - left) < _MIN_OVERLAP * smaller:
                continue
            new = image[top:bottom, left:right]
            old = crop[top - r0 : bottom - r0, left - c0 : right - c0]
            change = cv2.norm(new, old, cv2.NORM_L1) / new.size  # the mean absolute difference, exactly
            smallest = min(smallest, change)
        self._regions.append((box, image[row0:row1, col0:col1].copy()))
        if math.isfinite(smallest):
            self.last_change = smallest
        return smallest <= self.min_change
