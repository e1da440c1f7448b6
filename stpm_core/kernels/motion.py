"""Rigid motion per row (numba): a :class:`stpm_core.motion.MotionTransform` evaluated at many times.

A camera path asks for a moving thing's pose at every sample's own time: the camera at each
camera sample (``camera.camera_to_world``), an instance's normal matrix at each hit whose node
program reads it (``shading.normal_matrices``: Normal Map, Bump, Geometry).  numpy's
``MotionTransform.at`` followed by ``np.linalg.inv`` builds a dozen (n, 4) / (n, 3, 3)
temporaries and calls LAPACK once per matrix (about 5 us a row, measured on a 65k-row tile:
0.25 s); these kernels do the same maths in one pass (about 40 ns a row).

The keys are the transform's own (``MotionTransform._T`` (K, 3) translations, ``_Q`` (K, 4) unit
quaternions (w, x, y, z), ``_S`` (K, 3, 3) symmetric stretches, ``times`` (K,) knots); the float
operations follow ``MotionTransform.at`` (segment by ``searchsorted(side="right") - 1`` clipped
to [0, K - 2], fraction clipped to [0, 1], translation and stretch lerped as ``x0 (1 - a) + x1 a``,
slerp along the shorter arc, ``R @ S``), the products summed in index order; a BLAS matrix
product or numpy's SIMD sin may round differently (an ulp).
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit

__all__ = ["linear_at", "transform_rows", "camera_rows", "normal_matrix_rows"]

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


@njit(**_JIT)
def _segment(knots, f, l, t):
    """(i, a): key i in [f, l - 1] (global index) and fraction a in [0, 1] of time t between knots i, i + 1
    of a transform with keys f..l (l > f), as ``MotionTransform._segment``."""
    lo, hi = f, l + 1                       # searchsorted(knots[f:l + 1], t, side="right")
    while lo < hi:
        mid = (lo + hi) // 2
        if knots[mid] <= t:
            lo = mid + 1
        else:
            hi = mid
    i = min(max(lo - 1, f), l - 1)
    t0, t1 = knots[i], knots[i + 1]
    a = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
    return i, a


@njit(**_JIT)
def linear_at(knots, T, Q, S, f, l, t, M):
    """M (>= 3, >= 3) := the linear part R @ S at time t of the transform with keys f..l; returns the
    translation (3-tuple).  One key (f == l): the key itself."""
    if l == f:
        i, i1, a = f, f, 0.0
    else:
        i, a = _segment(knots, f, l, t)
        i1 = i + 1
    b = 1.0 - a
    # Rotation: slerp along the shorter arc (motion.quat_slerp)
    q0w, q0x, q0y, q0z = Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3]
    q1w, q1x, q1y, q1z = Q[i1, 0], Q[i1, 1], Q[i1, 2], Q[i1, 3]
    c = q0w * q1w + q0x * q1x + q0y * q1y + q0z * q1z
    if c < 0:
        q1w, q1x, q1y, q1z = -q1w, -q1x, -q1y, -q1z
    theta = math.acos(min(max(abs(c), -1.0), 1.0))
    sin_t = math.sin(theta)
    if sin_t < 1e-6:
        w0, w1 = b, a
    else:
        w0, w1 = math.sin(b * theta) / sin_t, math.sin(a * theta) / sin_t
    w = w0 * q0w + w1 * q1w
    x = w0 * q0x + w1 * q1x
    y = w0 * q0y + w1 * q1y
    z = w0 * q0z + w1 * q1z
    nq = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / nq, x / nq, y / nq, z / nq
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    # Stretch: lerp; M = R @ S
    for j in range(3):
        s0 = S[i, 0, j] * b + S[i1, 0, j] * a
        s1 = S[i, 1, j] * b + S[i1, 1, j] * a
        s2 = S[i, 2, j] * b + S[i1, 2, j] * a
        M[0, j] = r00 * s0 + r01 * s1 + r02 * s2
        M[1, j] = r10 * s0 + r11 * s1 + r12 * s2
        M[2, j] = r20 * s0 + r21 * s1 + r22 * s2
    return (T[i, 0] * b + T[i1, 0] * a, T[i, 1] * b + T[i1, 1] * a, T[i, 2] * b + T[i1, 2] * a)


@njit(**_JIT)
def transform_rows(knots, T, Q, S, times, out):
    """out (n, 4, 4) := ``MotionTransform.at(times)`` for times (n,) of one transform (keys (K,) knots,
    T (K, 3), Q (K, 4), S (K, 3, 3))."""
    l = knots.shape[0] - 1
    for k in range(times.shape[0]):
        tx, ty, tz = linear_at(knots, T, Q, S, l - l, l, times[k], out[k])   # (key 0 as int64: a literal 0 compiles a 2nd signature)
        out[k, 0, 3], out[k, 1, 3], out[k, 2, 3] = tx, ty, tz
        out[k, 3, 0], out[k, 3, 1], out[k, 3, 2], out[k, 3, 3] = 0.0, 0.0, 0.0, 1.0


@njit(**_JIT)
def camera_rows(knots, T, Q, S, times, R, pos):
    """The camera's pose at times (n,) (``camera.camera_to_world`` of a moving camera): R (n, 3, 3) the
    rotation part with unit columns (scale ignored; a column of length 0 is kept 0), pos (n, 3)."""
    l = knots.shape[0] - 1
    for k in range(times.shape[0]):
        tx, ty, tz = linear_at(knots, T, Q, S, l - l, l, times[k], R[k])
        pos[k, 0], pos[k, 1], pos[k, 2] = tx, ty, tz
        for j in range(3):
            s = max(math.sqrt(R[k, 0, j] * R[k, 0, j] + R[k, 1, j] * R[k, 1, j] + R[k, 2, j] * R[k, 2, j]), 1e-300)
            R[k, 0, j], R[k, 1, j], R[k, 2, j] = R[k, 0, j] / s, R[k, 1, j] / s, R[k, 2, j] / s


@njit(**_JIT)
def normal_matrix_rows(inst, times, NM0, moving, knots, T, Q, S, first, last, out):
    """out (m, 3, 3) := the object-to-world normal matrix (inverse transpose of the linear part) of hit r
    on instance inst[r] (m,) at times[r].

    NM0 (n_instances, 3, 3): each static instance's (``np.linalg.inv(M).T``, computed once);
    moving (n_instances,) int64: -1 static, else the instance's transform j, whose keys are
    first[j]..last[j] of knots, T, Q, S (the stacked keys of every moving instance).  A moving
    row's matrix: ``linear_at``, then the cofactors over the determinant (cof(M) / det M =
    (M^-1)^T)."""
    M = np.empty((3, 3))
    for r in range(inst.shape[0]):
        i = inst[r]
        j = moving[i]
        if j < 0:
            for a in range(3):
                for b in range(3):
                    out[r, a, b] = NM0[i, a, b]
            continue
        linear_at(knots, T, Q, S, first[j], last[j], times[r], M)
        c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
        c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
        c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
        c10 = M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]
        c11 = M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]
        c12 = M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]
        c20 = M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]
        c21 = M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]
        c22 = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
        det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
        s = 1.0 / det
        out[r, 0, 0], out[r, 0, 1], out[r, 0, 2] = c00 * s, c01 * s, c02 * s
        out[r, 1, 0], out[r, 1, 1], out[r, 1, 2] = c10 * s, c11 * s, c12 * s
        out[r, 2, 0], out[r, 2, 1], out[r, 2, 2] = c20 * s, c21 * s, c22 * s
