"""Uniform sampling of the solid angle a rectangle subtends (Urena, Fajardo and King, EGSR 2013).

Used for rectangular AREA lights: a point on the light chosen with density uniform in the solid
angle ``S`` the rectangle covers from the shading point, so the direct-light estimator's weight is
``L S`` (times the one-sided emitter's front test) instead of ``L cos_l A / d^2``, whose variance
explodes for a large light close to the surface (docs/lights-and-materials.md, "AREA sampling").

Notation (per query, vectorised over n): rectangle corner ``s`` and orthogonal edges ``e_x, e_y``
(full lengths), shading point ``o``.  Local frame: ``x = e_x / |e_x|``, ``y = e_y / |e_y|``,
``z = x cross y`` flipped so the rectangle lies at ``z0 = (s - o) . z <= 0``; corners from
``(x0, y0)`` to ``(x1, y1) = (x0 + |e_x|, y0 + |e_y|)``.  The spherical rectangle's inner normals
``n_i`` and angles ``g_i = acos(-n_i . n_{i+1})`` give ``S = g0 + g1 + g2 + g3 - 2 pi``; sampling
inverts the solid angle along x (``au = u S + k``), then y uniformly in ``h = y / sqrt(d^2 + y^2)``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["spherical_rect_sample"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def spherical_rect_sample(o: np.ndarray, s: np.ndarray, ex: np.ndarray, ey: np.ndarray, u: np.ndarray):
    """Points on rectangles uniform in the solid angle they subtend from o.

    Parameters
    ----------
    o : (n, 3) shading points; s : (n, 3) a corner of each rectangle; ex, ey : (n, 3) its two edges
        from that corner (full lengths, orthogonal); u : (n, 2) uniforms in [0, 1).

    Returns
    -------
    q : (n, 3) points on the rectangles; S : (n,) solid angle (sr) each rectangle subtends from o
        (the density of q is 1 / S per steradian).  S is 0 where o lies in the rectangle's plane.
    """
    lx, ly = np.linalg.norm(ex, axis=-1), np.linalg.norm(ey, axis=-1)
    x, y = _unit(ex), _unit(ey)
    z = np.cross(x, y)
    d = s - o
    z0 = np.einsum("ij,ij->i", d, z)
    flip = z0 > 0.0
    z = np.where(flip[:, None], -z, z)
    z0 = np.where(flip, -z0, z0)
    x0 = np.einsum("ij,ij->i", d, x)
    y0 = np.einsum("ij,ij->i", d, y)
    x1, y1 = x0 + lx, y0 + ly
    zero = np.zeros_like(z0)
    # Inner normals of the four great-circle edges of the spherical rectangle
    n0 = _unit(np.stack([zero, z0, -y0], axis=-1))
    n1 = _unit(np.stack([-z0, zero, x1], axis=-1))
    n2 = _unit(np.stack([zero, -z0, y1], axis=-1))
    n3 = _unit(np.stack([z0, zero, -x0], axis=-1))

    def angle(a, b):
        return np.arccos(np.clip(-np.einsum("ij,ij->i", a, b), -1.0, 1.0))

    g0, g1, g2, g3 = angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0)
    b0, b1 = n0[:, 2], n2[:, 2]
    k = 2.0 * np.pi - g2 - g3
    S = np.maximum(g0 + g1 - k, 0.0)
    # x by the solid angle's cumulative, then y by h = y / sqrt(d^2 + y^2)
    au = u[:, 0] * S + k
    sin_au = np.sin(au)
    fu = (np.cos(au) * b0 - b1) / np.where(sin_au == 0.0, 1e-300, sin_au)
    cu = np.clip(np.sign(fu) / np.sqrt(fu * fu + b0 * b0 + 1e-300), -1.0, 1.0)
    cu = np.where(fu == 0.0, 0.0, cu)
    xu = np.clip(-(cu * z0) / np.sqrt(np.maximum(1.0 - cu * cu, 1e-300)), x0, x1)
    dd = np.sqrt(xu * xu + z0 * z0)
    h0 = y0 / np.sqrt(dd * dd + y0 * y0 + 1e-300)
    h1 = y1 / np.sqrt(dd * dd + y1 * y1 + 1e-300)
    hv = h0 + u[:, 1] * (h1 - h0)
    hv2 = hv * hv
    yv = np.where(hv2 < 1.0 - 1e-12, hv * dd / np.sqrt(np.maximum(1.0 - hv2, 1e-300)), y1)
    yv = np.clip(yv, y0, y1)
    q = o + xu[:, None] * x + yv[:, None] * y + z0[:, None] * z
    return q, S
