"""Motion across the shutter: rigid transforms sampled at K times, interpolated
decomposed (translation lerp, rotation slerp, scale/shear lerp).

Time convention used everywhere in ``stpm_core``: **normalised shutter time**
``u`` in [0, 1], 0 = shutter opens, 1 = shutter closes (see :mod:`stpm_core.shutter`
for the map to frames).  A transform with one sample is static.

Decomposition: ``M = T @ R @ S`` with ``R`` a rotation (unit quaternion) and
``S`` a symmetric stretch (polar decomposition), so any affine matrix with
positive determinant round-trips exactly at the sample times.  Between samples
``T`` and ``S`` are lerped and ``R`` is slerped along the shorter arc.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError

__all__ = ["MotionTransform", "quat_from_matrix", "matrix_from_quat", "quat_slerp"]


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) as (w, x, y, z)."""
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    # Four candidate formulas; pick per element the numerically largest pivot.
    q = np.empty(R.shape[:-2] + (4,))
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    which = np.argmax(cand, axis=-1)
    s0 = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2
    s1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2
    s2 = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-300)) * 2
    s3 = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-300)) * 2
    r = R
    q0 = np.stack([0.25 * s0, (r[..., 2, 1] - r[..., 1, 2]) / s0,
                   (r[..., 0, 2] - r[..., 2, 0]) / s0, (r[..., 1, 0] - r[..., 0, 1]) / s0], -1)
    q1 = np.stack([(r[..., 2, 1] - r[..., 1, 2]) / s1, 0.25 * s1,
                   (r[..., 0, 1] + r[..., 1, 0]) / s1, (r[..., 0, 2] + r[..., 2, 0]) / s1], -1)
    q2 = np.stack([(r[..., 0, 2] - r[..., 2, 0]) / s2, (r[..., 0, 1] + r[..., 1, 0]) / s2,
                   0.25 * s2, (r[..., 1, 2] + r[..., 2, 1]) / s2], -1)
    q3 = np.stack([(r[..., 1, 0] - r[..., 0, 1]) / s3, (r[..., 0, 2] + r[..., 2, 0]) / s3,
                   (r[..., 1, 2] + r[..., 2, 1]) / s3, 0.25 * s3], -1)
    q = np.choose(which[..., None], [q0, q1, q2, q3])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) (w, x, y, z) -> rotation matrices (..., 3, 3)."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quat_slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Slerp (n, 4) x (n, 4) by fractions a (n,) along the shorter arc -> (n, 4)."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where((dot < 0)[..., None], -q1, q1)
    dot = np.abs(dot)
    a = a[..., None]
    theta = np.arccos(np.clip(dot, -1.0, 1.0))[..., None]
    sin_t = np.sin(theta)
    small = sin_t < 1e-6
    safe = np.where(small, 1.0, sin_t)
    w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / safe)
    w1 = np.where(small, a, np.sin(a * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _polar(M3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polar decomposition of (K, 3, 3): M = R @ S, R rotation, S symmetric."""
    U, sig, Vt = np.linalg.svd(M3)
    d = np.sign(np.linalg.det(U @ Vt))
    # Keep R a proper rotation; a mirrored matrix puts the reflection into S.
    U = U.copy()
    U[:, :, 2] *= d[:, None]
    R = U @ Vt
    S = np.swapaxes(R, -1, -2) @ M3
    return R, 0.5 * (S + np.swapaxes(S, -1, -2))


@dataclass
class MotionTransform:
    """An object-to-world affine transform sampled at K shutter times.

    Attributes
    ----------
    times : (K,) float64, increasing, in [0, 1] (normalised shutter time).
    matrices : (K, 4, 4) float64 object-to-world matrices at those times.

    ``K == 1`` means static: :meth:`at` then returns the one matrix for every
    time, and callers may test :attr:`is_static` to skip motion work.
    """

    times: np.ndarray
    matrices: np.ndarray
    _T: np.ndarray = field(init=False, repr=False)
    _Q: np.ndarray = field(init=False, repr=False)
    _S: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.times = np.atleast_1d(np.asarray(self.times, dtype=np.float64))
        self.matrices = np.asarray(self.matrices, dtype=np.float64).reshape(-1, 4, 4)
        if self.matrices.shape[0] != self.times.shape[0]:
            raise SceneError(f"transform has {self.matrices.shape[0]} matrices but {self.times.shape[0]} times")
        if not np.all(np.isfinite(self.matrices)) or not np.all(np.isfinite(self.times)):
            raise SceneError("transform contains NaN or inf")
        if self.times.shape[0] > 1 and np.any(np.diff(self.times) <= 0):
            raise SceneError("transform times must be strictly increasing")
        self._T = self.matrices[:, :3, 3].copy()
        R, S = _polar(self.matrices[:, :3, :3])
        Q = quat_from_matrix(R)
        # Keep consecutive quaternions in the same hemisphere.
        for i in range(1, len(Q)):
            if np.dot(Q[i - 1], Q[i]) < 0:
                Q[i] = -Q[i]
        self._Q, self._S = Q, S
        # Collapse samples that are all identical: a static object pays no motion cost.
        if self.times.shape[0] > 1 and np.allclose(self.matrices, self.matrices[:1], rtol=0, atol=1e-12 * (1 + np.abs(self.matrices).max())):
            self.times = self.times[:1]
            self.matrices = self.matrices[:1]
            self._T, self._Q, self._S = self._T[:1], self._Q[:1], self._S[:1]

    @classmethod
    def static(cls, matrix: np.ndarray | None = None) -> "MotionTransform":
        """A transform that does not move (identity by default)."""
        m = np.eye(4) if matrix is None else np.asarray(matrix, dtype=np.float64)
        return cls(times=np.array([0.5]), matrices=m[None])

    @property
    def is_static(self) -> bool:
        return self.times.shape[0] == 1

    def _segment(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment index i (n,) and fraction a (n,) such that t lies in [times[i], times[i+1]]."""
        K = self.times.shape[0]
        i = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, K - 2)
        t0, t1 = self.times[i], self.times[i + 1]
        a = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
        return i, a

    def at(self, t: np.ndarray | float) -> np.ndarray:
        """Object-to-world matrices at times t: (n,) -> (n, 4, 4) float64 (scalar -> (4, 4))."""
        scalar = np.ndim(t) == 0
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if self.is_static:
            out = np.broadcast_to(self.matrices[0], (t.shape[0], 4, 4)).copy()
        else:
            i, a = self._segment(t)
            T = self._T[i] * (1 - a)[:, None] + self._T[i + 1] * a[:, None]
            R = matrix_from_quat(quat_slerp(self._Q[i], self._Q[i + 1], a))
            S = self._S[i] * (1 - a)[:, None, None] + self._S[i + 1] * a[:, None, None]
            out = np.zeros((t.shape[0], 4, 4))
            out[:, :3, :3] = R @ S
            out[:, :3, 3] = T
            out[:, 3, 3] = 1.0
        return out[0] if scalar else out

    def inverse_at(self, t: np.ndarray | float) -> np.ndarray:
        """World-to-object matrices at times t, same shapes as :meth:`at`."""
        return np.linalg.inv(self.at(t))

    def transform_points(self, p: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Map object-space points p (n, 3) at times t (n,) to world space (n, 3)."""
        M = self.at(t)
        return np.einsum("nij,nj->ni", M[:, :3, :3], p) + M[:, :3, 3]

    def transform_dirs(self, d: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Map object-space directions d (n, 3) at times t (n,) to world space (n, 3) (not normalised)."""
        M = self.at(t)
        return np.einsum("nij,nj->ni", M[:, :3, :3], d)

    def bounds_of(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World bounds (3,), (3,) of an object-space box over the whole shutter.

        Samples the motion densely (rotation makes the swept box non-linear), then
        pads by 1 % of the box diagonal.
        """
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        M = self.__dict__.get("_bounds_samples")
        if M is None:
            # The 33 sampled matrices, kept: scenes ask for the same bounds several times
            # per render, and a scene may hold thousands of moving instances
            M = self.__dict__["_bounds_samples"] = self.at(np.linspace(0, 1, 1 if self.is_static else 33))
        pts = np.einsum("kij,cj->kci", M[:, :3, :3], corners) + M[:, None, :3, 3]
        pts = pts.reshape(-1, 3)
        a, b = pts.min(0), pts.max(0)
        pad = 0.0 if self.is_static else 0.01 * np.linalg.norm(b - a)
        return a - pad, b + pad
