"""Sampling primitives: seeded random streams, stratified samples and warps
from the unit square to directions.

Every warp takes uniform samples ``u`` of shape (n, 2) in [0, 1)^2 and returns
points in a *local* frame (z = the axis of the hemisphere / cone); rotate them
into world space with :func:`orthonormal_basis` and :func:`to_world`.

Densities (solid angle, sr^-1):

* :func:`cosine_hemisphere`  p(w) = cos(theta) / pi
* :func:`uniform_sphere`     p(w) = 1 / (4 pi)
* :func:`uniform_cone`       p(w) = 1 / (2 pi (1 - cos_max))
* :func:`concentric_disk`    p(x) = 1 / pi on the unit disk (area measure)
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "rng_for", "skip_uniforms", "orthonormal_basis", "to_world", "cosine_hemisphere", "uniform_sphere",
    "uniform_cone", "uniform_cone_pdf", "concentric_disk", "stratified_1d", "stratified_2d",
]


def rng_for(seed: int, *stream: int) -> np.random.Generator:
    """A generator for one named stream of randomness.

    ``SeedSequence([seed, *stream])``: the same seed and stream always give the
    same numbers, whatever the thread count or the order streams are made in.
    ``stream`` entries are non-negative ints (e.g. pass index, tile index).
    """
    entropy = [int(seed) & 0xFFFFFFFFFFFFFFFF] + [int(s) & 0xFFFFFFFFFFFFFFFF for s in stream]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(entropy)))


def skip_uniforms(rng: np.random.Generator, n: int) -> None:
    """Move ``rng`` past n float64 uniforms without making them.

    ``rng.random`` takes one 64-bit output of the bit generator per float64,
    so advancing the bit generator by n leaves the stream exactly where
    ``rng.random(n)`` would (tests/test_kernel_paths_units.py checks it).  For
    numbers a value ignores (times of an instant shutter, uniforms of a point
    light): the rest of the stream, and so the image, stays the same.
    """
    rng.bit_generator.advance(int(n))


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent frame for unit normals n (n, 3) -> (tangent (n, 3), bitangent (n, 3)).

    (tangent, bitangent, n) is right-handed and orthonormal for every unit n,
    including n = +z and n = -z (Duff et al. 2017, "Building an orthonormal
    basis, revisited": branch-free, no division by a small number).
    """
    n = np.asarray(n, dtype=np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    tangent = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    bitangent = np.stack([b, sign + y * y * a, -y], axis=-1)
    return tangent, bitangent


def to_world(local: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotate local directions (n, 3) (z = axis) into the frame around unit n (n, 3)."""
    t, b = orthonormal_basis(n)
    return local[..., 0:1] * t + local[..., 1:2] * b + local[..., 2:3] * np.asarray(n, dtype=np.float64)


def concentric_disk(u: np.ndarray) -> np.ndarray:
    """Uniform points on the unit disk (n, 2) from u (n, 2) (Shirley-Chiu map, low distortion)."""
    u = np.asarray(u, dtype=np.float64)
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    # Pick the wedge: |a| > |b| -> r = a, phi = pi/4 * b/a; else r = b, phi = pi/2 - pi/4 * a/b
    first = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0.0, 1.0, a)
    safe_b = np.where(b == 0.0, 1.0, b)
    r = np.where(first, a, b)
    phi = np.where(first, 0.25 * np.pi * (b / safe_a), 0.5 * np.pi - 0.25 * np.pi * (a / safe_b))
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions about +z (n, 3); pdf = cos(theta) / pi per sr."""
    d = concentric_disk(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - np.sum(d * d, axis=-1)))
    return np.concatenate([d, z[..., None]], axis=-1)


def uniform_sphere(u: np.ndarray) -> np.ndarray:
    """Uniform directions on the unit sphere (n, 3); pdf = 1 / (4 pi)."""
    u = np.asarray(u, dtype=np.float64)
    z = 1.0 - 2.0 * u[..., 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def uniform_cone(u: np.ndarray, cos_max) -> np.ndarray:
    """Uniform directions in the cone about +z of half-angle acos(cos_max) (n, 3).

    ``cos_max`` is a scalar or (n,).  pdf = 1 / (2 pi (1 - cos_max)) per sr
    (see :func:`uniform_cone_pdf`); cos_max = 1 returns +z exactly.
    """
    u = np.asarray(u, dtype=np.float64)
    cos_max = np.asarray(cos_max, dtype=np.float64)
    # cos(theta) uniform in [cos_max, 1]
    cos_t = 1.0 - u[..., 0] * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * u[..., 1]
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)


def uniform_cone_pdf(cos_max) -> np.ndarray:
    """Solid-angle density 1 / (2 pi (1 - cos_max)) of :func:`uniform_cone` (inf for cos_max = 1)."""
    omega = 2.0 * np.pi * (1.0 - np.asarray(cos_max, dtype=np.float64))
    with np.errstate(divide="ignore"):
        return 1.0 / omega


def stratified_1d(n: int, rng: np.random.Generator) -> np.ndarray:
    """n jittered samples in [0, 1): one uniformly in each stratum [i/n, (i+1)/n), shuffled -> (n,)."""
    s = (np.arange(n) + rng.random(n)) / n
    return rng.permutation(s)


def stratified_2d(n_per_pixel: int, rng: np.random.Generator) -> np.ndarray:
    """n jittered samples in [0, 1)^2 -> (n, 2), shuffled.

    A square sqrt(n) x sqrt(n) grid when n is a square; otherwise the largest
    grid rows x cols <= n (rows = floor(sqrt n), cols = n // rows) plus the
    remaining samples drawn uniformly, so any n works.
    """
    n = int(n_per_pixel)
    rows = max(1, int(np.floor(np.sqrt(n))))
    cols = max(1, n // rows)
    m = rows * cols
    iy, ix = np.divmod(np.arange(m), cols)
    jitter = rng.random((m, 2))
    grid = np.stack([(ix + jitter[:, 0]) / cols, (iy + jitter[:, 1]) / rows], axis=-1)
    extra = rng.random((n - m, 2))
    return rng.permutation(np.concatenate([grid, extra], axis=0))[:n]
