"""The renderer's compiled kernels: the painter's algorithm over a patch, point by point, and the frame's background.

:mod:`pectoral_gym.hardware.vision.scene` calls these; they give the bits of its numpy reference (the same scalar
``+ - * /`` in the same order, no fast-math; what numpy's libm computes, ``cos``/``sin`` of the heading and the
homography's matrix product, stays in numpy and is passed in). ``tests/test_scene_kernels.py`` holds the frames to
the numpy renderer byte for byte.

The scene's shapes reach the kernels as ``shapes``, a float64 array (:data:`SHAPE_FIELDS` in order) and
``occluders`` ``(k, 3)``: centre x, centre y, squared radius [m, m, m^2]; ``index`` (uint8) is the palette index of
each painting step: wall, floor, body, front marker, its strip, back marker, its strip, then the occluders.
"""

from __future__ import annotations

import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["SHAPE_FIELDS", "average_whole", "copy_runs", "paint_centres", "paint_samples", "sample_points"]

# The pose's and the shapes' scalars, each computed in Python as the numpy reference computes it.
SHAPE_FIELDS = (
    "x", "y", "cos", "sin", "half_length", "half_width", "tank_length", "tank_width",
    "front_offset", "back_offset", "marker_radius_sq", "strip_half_width", "strip_top",
    "front_hidden", "front_strip_bottom", "back_hidden", "back_strip_bottom", "reach_sq",
)


@njit(inline="always")
def _paint(tx: float, ty: float, shapes: np.ndarray, occluders: np.ndarray, index: np.ndarray) -> np.uint8:
    """Palette index of the scene at tank point ``(tx, ty)``: the last painting step whose shape holds it."""
    label = index[0]
    if tx >= 0 and tx <= shapes[6] and ty >= 0 and ty <= shapes[7]:
        label = index[1]
    dx = tx - shapes[0]
    dy = ty - shapes[1]
    if dx * dx + dy * dy <= shapes[17]:  # else beyond every shape of the fish (with a margin over rounding)
        bx = shapes[2] * dx + shapes[3] * dy
        by = -shapes[3] * dx + shapes[2] * dy
        ex = bx / shapes[4]
        ey = by / shapes[5]
        if ex * ex + ey * ey <= 1:
            label = index[2]
        for marker in range(2):
            mx = bx - shapes[8 + marker]
            if mx * mx + by * by <= shapes[10]:
                label = index[3 + 2 * marker]
            if shapes[13 + 2 * marker] > 0:
                if abs(mx) <= shapes[11] and by >= shapes[14 + 2 * marker] and by <= shapes[12]:
                    label = index[4 + 2 * marker]
    for k in range(occluders.shape[0]):
        ox = tx - occluders[k, 0]
        oy = ty - occluders[k, 1]
        if ox * ox + oy * oy <= occluders[k, 2]:
            label = index[7 + k]
    return label


@njit
def paint_centres(grid: np.ndarray, v0: int, u0: int, height: int, width: int, shapes: np.ndarray,
                  occluders: np.ndarray, index: np.ndarray, opaque: np.ndarray,
                  palette: np.ndarray, colour: np.ndarray, edge: np.ndarray) -> int:
    """Label the pixel centres of a box and find the pixels a shape's edge may cross.

    ``grid`` is the camera's pixel grid (tank points of the centres from one pixel before each image edge); the
    box's ``height x width`` pixels start at pixel ``(u0, v0)``. Writes each pixel's centre's colour (its
    label's ``palette`` row) into ``colour`` ``(height, width, 3)`` and, into ``edge`` ``(height * width, 2)``,
    the (row, column) of every pixel that is not uniform: its label differs from one of its eight neighbours',
    or its colour is not a colour (``opaque`` is False for a palette entry with a NaN channel). Returns how
    many rows of ``edge`` it wrote.
    """
    centres = np.empty((height + 2, width + 2), dtype=np.uint8)
    points = grid[v0:v0 + height + 2, u0:u0 + width + 2]  # indices from 0: no negative-index wrap tests
    for r in range(height + 2):
        for c in range(width + 2):
            centres[r, c] = _paint(points[r, c, 0], points[r, c, 1], shapes, occluders, index)
    count = 0
    for r in range(height):
        for c in range(width):
            label = centres[r + 1, c + 1]
            for channel in range(3):
                colour[r, c, channel] = palette[label, channel]
            uniform = opaque[label]
            for dr in range(3):
                for dc in range(3):
                    if centres[r + dr, c + dc] != label:
                        uniform = False
            if not uniform:
                edge[count, 0] = r
                edge[count, 1] = c
                count += 1
    return count


@njit
def sample_points(edge: np.ndarray, count: int, u0: int, v0: int, offsets: np.ndarray) -> np.ndarray:
    """Pixel coordinates ``(count * s * s, 2)`` of the supersamples of the first ``count`` pixels of ``edge``.

    Sample ``(a, b)`` of pixel (row, column) lies at ``(column + u0 + offsets[b], row + v0 + offsets[a])``.
    """
    s = offsets.shape[0]
    points = np.empty((count * s * s, 2))
    for i in range(count):
        u = float(edge[i, 1] + u0)
        v = float(edge[i, 0] + v0)
        for a in range(s):
            for b in range(s):
                points[(i * s + a) * s + b, 0] = u + offsets[b]
                points[(i * s + a) * s + b, 1] = v + offsets[a]
    return points


@njit
def paint_samples(homogeneous: np.ndarray, offset: np.ndarray, samples: int, shapes: np.ndarray,
                  occluders: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Labels ``(n // samples, samples)`` of the points ``homogeneous`` ``(n, 3)``, ``samples`` per pixel.

    ``homogeneous`` is the pixel points times the pixel-to-tank homography's first two columns (the matrix
    product numpy computed), ``offset`` its third column: a point's tank coordinates are its first two
    components plus their offsets, each divided by the third plus its offset (the homography's own order).
    """
    labels = np.empty((homogeneous.shape[0] // samples, samples), dtype=np.uint8)
    for i in range(labels.shape[0]):
        for j in range(samples):
            point = homogeneous[i * samples + j]
            weight = point[2] + offset[2]
            tx = (point[0] + offset[0]) / weight
            ty = (point[1] + offset[1]) / weight
            labels[i, j] = _paint(tx, ty, shapes, occluders, index)
    return labels


@njit
def average_whole(labels: np.ndarray, palette: np.ndarray, edge: np.ndarray, colour: np.ndarray) -> None:
    """Write each edge pixel's mean sample colour into ``colour`` ``(height, width, 3)``.

    For a palette of whole channel values only: the sum of a pixel's samples is then exact in any order, the
    same as the reference's count-weighted sum, and one division by the sample count gives its bits.
    """
    samples = labels.shape[1]
    for i in range(labels.shape[0]):
        for channel in range(3):
            total = 0.0
            for j in range(samples):
                total += palette[labels[i, j], channel]
            colour[edge[i, 0], edge[i, 1], channel] = total / samples


@njit
def copy_runs(tables: np.ndarray, runs: np.ndarray, start: int, frame: np.ndarray) -> None:
    """Fill the flat ``frame`` from the rounded tables: run ``(first, end, k)`` reads row ``k`` of ``tables``.

    ``tables`` ``(colours, n)`` holds each background colour plus noise; the frame's byte ``i`` of a run of
    colour ``k`` is ``tables[k, start + i]``.
    """
    for r in range(runs.shape[0]):
        first, end = runs[r, 0], runs[r, 1]
        target = frame[first:end]
        source = tables[runs[r, 2], start + first:start + end]
        for i in range(end - first):  # from 0: no negative-index wrap test, so the loop vectorises
            target[i] = source[i]
