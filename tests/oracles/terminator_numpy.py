"""The numpy shadow-terminator offset the compiled kernels (``kernels.paths.smooth_surface_heights``,
``terminator_rows``, ``terminator_origin``, ``shading_offset_factor``) are tested against.

Written from Cycles' description (``light/sample.h``: ``shadow_ray_smooth_surface_offset``,
``shadow_ray_offset``; ``closure/bsdf.h``: ``shift_cos_in``; Hanika 2021, "Hacking the shadow
terminator"), vectorised over rows, with its own arrangement of the sums: the parabola from the
corners' tangent planes, the local linear envelope per corner, the cutoff ramp.
"""
from __future__ import annotations

import numpy as np

__all__ = ["smooth_surface_offset", "shadow_ray_origin", "shading_offset_factor"]


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def smooth_surface_offset(V: np.ndarray, N: np.ndarray, u: np.ndarray, v: np.ndarray, front: np.ndarray):
    """Lift vectors (n, 3) (units of V) of points with barycentrics u, v (n,) on triangles V (n, 3, 3)
    with unit corner normals N (n, 3, 3): n h, n the interpolated normal (not normalised), h the
    front (``front`` (n,) bool: seen from the normals' side) or back height."""
    w = np.stack([1.0 - u - v, u, v], axis=1)                        # (n, 3)
    P = np.einsum("nk,nki->ni", w, V)
    n = np.einsum("nk,nki->ni", w, N)
    a = _dot(N[:, 2] - N[:, 0], V[:, 0] - V[:, 2])
    b = _dot(N[:, 2] - N[:, 1], V[:, 1] - V[:, 2])
    c = _dot(N[:, 1] - N[:, 0], V[:, 1] - V[:, 0])
    h_par = a * w[:, 0] * (w[:, 0] - 1) + (a + b + c) * w[:, 0] * w[:, 1] + b * w[:, 1] * (w[:, 1] - 1)
    # D[n, i, j] = (V_j - V_i) . N_i: corner j's height above corner i's tangent plane
    D = np.einsum("nji,nki->nkj", V, N) - _dot(V, N)[:, :, None]
    eye = np.eye(3, dtype=bool)[None]
    e_front = np.maximum(np.where(eye, -np.inf, D).max(axis=2), 0.0)
    e_back = np.maximum(np.where(eye, -np.inf, -D).max(axis=2), 0.0)
    q = _dot(V - P[:, None, :], N)                                   # (n, 3): corner i's plane over P
    h_front = np.maximum(np.maximum(q + e_front, 0.0).min(axis=1), 0.5 * h_par)
    h_back = np.minimum(-np.maximum(-q + e_back, 0.0).min(axis=1), 0.5 * h_par)
    return n * np.where(front, h_front, h_back)[:, None], n


def shadow_ray_origin(p, ns, ng, d, wi, V, N, u, v, cutoff):
    """Shadow-ray origins (n, 3) of hit points p (n, 3) toward wi (n, 3) (unit) on smooth triangles
    (world space V, N as :func:`smooth_surface_offset`), hit by rays d (n, 3), shading normal ns,
    geometric ng (n, 3), object cutoff (scalar > 0)."""
    flip = np.where(_dot(ng, d) > 0, -1.0, 1.0)[:, None]
    Ns, Ng = ns * flip, ng * flip
    NL = _dot(Ns, wi)
    transmit = NL < 0
    NL = np.abs(NL)
    Ng = np.where(transmit[:, None], -Ng, Ng)
    NgL = _dot(Ng, wi)
    amount = np.where(NL < cutoff, np.clip(2.0 - (NgL + NL) / cutoff, 0, 1), np.clip(1.0 - NgL / cutoff, 0, 1))
    _, n = smooth_surface_offset(V, N, u, v, np.ones(len(u), bool))
    front = _dot(n, Ng) > 0
    lift, _ = smooth_surface_offset(V, N, u, v, front)
    return p + amount[:, None] * lift


def shading_offset_factor(s: float, ns, ng, d, wi):
    """Cycles' shading-offset factor (n,) for offset s: multiplier m = 1 / (1 - s / 2), cos = N . wi
    (N facing the viewer), max(cos(m arccos(cos)), 0) / cos where cos > 0, else 1."""
    m = 1.0 / (1.0 - 0.5 * s)
    flip = np.where(_dot(ng, d) > 0, -1.0, 1.0)
    cos = flip * _dot(ns, wi)
    c = np.minimum(np.where(cos > 0, cos, 1.0), 1.0)
    return np.where(cos > 0, np.maximum(np.cos(m * np.arccos(c)), 0.0) / c, 1.0)
