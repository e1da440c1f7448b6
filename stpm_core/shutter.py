"""The camera shutter: when it is open, and how exposure is weighted in time.

Normalised shutter time ``u`` in [0, 1] maps to frames as
``frame = open + u * (close - open)``.  Blender's shutter curve (a weight over
the open interval, default flat) is the density of ``u``; camera samples and
photon paths both draw their time from it by its inverse CDF, so the pixel
value is the curve-weighted time average of radiance (see docs/time.md).

The curve is piecewise linear between equally spaced knots.  Every quantity
derived from it (density, CDF, inverse CDF, integrals against it) works on the
curve divided by its maximum, so weights of any finite scale (5e-324 or
1.7e308) give the same density, and one set of tables (``_w``, ``_cdf``,
``_total``) serves the forward and the inverse map, which therefore agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError

__all__ = ["Shutter", "SHUTTER_FRAME_LIMIT"]

#: Largest |open| / |close| in frames: Blender's frame limit (1048574) with room for a long shutter.
SHUTTER_FRAME_LIMIT = 2 ** 21

_GL2 = 1.0 / np.sqrt(3.0)      # 2-point Gauss-Legendre nodes at mid -+ half * _GL2, weights 1 (exact for cubics)


@dataclass
class Shutter:
    """Shutter interval and curve.

    Attributes
    ----------
    open, close : float
        Frame numbers (fractional) at which the shutter opens and closes;
        ``close >= open``.  Equal values mean no motion blur (one instant).
    curve : (m,) float64 or None
        Non-negative weights at ``m >= 2`` equally spaced points of [0, 1],
        linear in between (Blender's ``motion_blur_shutter_curve`` sampled),
        kept as given; only their shape matters.  ``None`` is a box: every
        instant weighs the same.
    """

    open: float = 1.0
    close: float = 1.0
    curve: np.ndarray | None = None
    _cdf_u: np.ndarray = field(init=False, repr=False)   # (m,) knots u_j = j / (m - 1)
    _cdf: np.ndarray = field(init=False, repr=False)     # (m,) CDF at the knots, 0 .. 1
    _w: np.ndarray = field(init=False, repr=False, compare=False)        # (m,) curve / max(curve), in [0, 1]
    _total: float = field(init=False, repr=False, compare=False)        # integral of _w over [0, 1]
    _seg_range: tuple = field(init=False, repr=False, compare=False)    # first, last segment with mass
    _tree: tuple | None = field(default=None, init=False, repr=False, compare=False)    # see _segment_tree

    def __post_init__(self) -> None:
        if not (np.isfinite(self.open) and np.isfinite(self.close)):
            raise SceneError("shutter.open/close must be finite")
        for name in ("open", "close"):
            v = float(getattr(self, name))
            if not -SHUTTER_FRAME_LIMIT <= v <= SHUTTER_FRAME_LIMIT:
                raise SceneError(f"shutter.{name} must be a frame number in [{-SHUTTER_FRAME_LIMIT}, "
                                 f"{SHUTTER_FRAME_LIMIT}], got {v:g}")
        if self.close < self.open:
            raise SceneError(f"shutter closes ({self.close}) before it opens ({self.open})")
        if self.curve is None:
            return
        c = np.asarray(self.curve, dtype=np.float64).ravel()
        if c.shape[0] < 2 or not np.all(np.isfinite(c)) or np.any(c < 0) or not c.max() > 0:
            raise SceneError("shutter.curve must have >= 2 finite non-negative weights, not all zero")
        self.curve = c
        w = c / c.max()                                   # the knot holding the maximum is exactly 1
        u = np.linspace(0.0, 1.0, c.shape[0])
        seg = 0.5 * (w[1:] + w[:-1]) * np.diff(u)         # segment areas; >= h/2 next to the maximum
        cdf = np.concatenate([[0.0], np.cumsum(seg)])
        total = float(cdf[-1])
        cdf = cdf / total
        cdf[-1] = 1.0
        mass = np.flatnonzero(seg > 0.0)
        self._cdf_u, self._cdf, self._w, self._total = u, cdf, w, total
        self._seg_range = (int(mass[0]), int(mass[-1]))

    @property
    def length(self) -> float:
        """Shutter length in frames."""
        return float(self.close - self.open)

    @property
    def is_instant(self) -> bool:
        """True when the shutter has (numerically) zero length: no motion blur."""
        return self.length <= 0.0

    @property
    def is_box(self) -> bool:
        """True when every instant of [0, 1] weighs the same: no curve, or a flat one (density 1)."""
        return self.curve is None or bool(np.all(self._w == 1.0))

    @property
    def support(self) -> tuple[float, float]:
        """(lo, hi): the smallest interval of [0, 1] outside which the density is 0."""
        if self.curve is None:
            return 0.0, 1.0
        first, last = self._seg_range
        return float(self._cdf_u[first]), float(self._cdf_u[last + 1])

    def to_frame(self, u: np.ndarray) -> np.ndarray:
        """Normalised time (n,) -> frame number (n,)."""
        return self.open + np.asarray(u) * (self.close - self.open)

    def sample(self, xi: np.ndarray) -> np.ndarray:
        """Map uniform numbers xi (n,) in [0, 1] to shutter times u (n,) with the curve's density.

        Stratified ``xi`` stays stratified (the map is monotone).  For a box
        shutter this is the identity; for a zero-length shutter it returns 0.5.
        With a curve, ``sample(0)`` and ``sample(1)`` are the ends of
        :attr:`support`, every u lies in it, and ``cdf(sample(xi)) = xi``.
        """
        xi = np.asarray(xi, dtype=np.float64)
        if self.is_instant:
            return np.full(xi.shape, 0.5)
        if self.curve is None:
            return xi.copy()
        xi = np.clip(xi, 0.0, 1.0)
        # Segment i holding xi, kept among the segments with mass (trailing / leading zeros)
        first, last = self._seg_range
        i = np.clip(np.searchsorted(self._cdf, xi, side="right") - 1, first, last)
        u0, u1 = self._cdf_u[i], self._cdf_u[i + 1]
        w0, w1 = self._w[i], self._w[i + 1]
        h = u1 - u0
        target = (xi - self._cdf[i]) * self._total        # area of _w to cover inside the segment
        slope = (w1 - w0) / h
        # Solve w0 x + slope x^2 / 2 = target for x in [0, h], in the form without cancellation:
        # x = 2 target / (w0 + sqrt(w0^2 + 2 slope target)); the denominator is 0 only when target is.
        den = w0 + np.sqrt(np.maximum(w0 * w0 + 2.0 * slope * target, 0.0))
        x = np.divide(2.0 * target, den, out=np.zeros_like(den), where=den > 0.0)
        u = np.minimum(u0 + np.clip(x, 0.0, h), u1)
        return np.where(xi >= self._cdf[i + 1], u1, u)   # the support's end exactly (xi = 1)

    def cdf(self, u: np.ndarray) -> np.ndarray:
        """CDF P(u) (n,) of the shutter time at u (n,) clipped to [0, 1]: exact, piecewise quadratic.

        The inverse of :meth:`sample` (same tables): ``cdf(sample(xi)) = xi`` to rounding.
        """
        u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        if self.curve is None:
            return u
        uu, w, cdf = self._cdf_u, self._w, self._cdf
        i = np.clip(np.searchsorted(uu, u, side="right") - 1, 0, len(uu) - 2)
        x = u - uu[i]
        slope = (w[i + 1] - w[i]) / (uu[i + 1] - uu[i])
        return np.minimum(cdf[i] + x * (w[i] + 0.5 * slope * x) / self._total, cdf[i + 1])

    def density(self, u: np.ndarray) -> np.ndarray:
        """Probability density of shutter time at u (n,); integrates to 1 over [0, 1]."""
        u = np.asarray(u, dtype=np.float64)
        if self.curve is None:
            return np.ones_like(u)
        return np.interp(u, self._cdf_u, self._w) / self._total

    def parabola_integral(self, t: np.ndarray, half_width: np.ndarray, lo=0.0, hi=1.0) -> np.ndarray:
        """Exact ``I = integral over [a, b] of (h^2 - (tau - t)^2) g(tau) dtau`` (n,), shutter^3.

        t (n,) times, half_width h (n,) >= 0; ``[a, b] = [t - h, t + h]`` cut to [lo, hi] (scalars or
        (n,), within [0, 1]; default the shutter), where the
        parabola is >= 0; g the density.  ``pi s^2 I`` is KD4D's clipped ball measure
        (``slab_ball_volume``, docs/photon-mapping.md).

        * box: ``(x_b - x_a) (h^2 - (x_a^2 + x_a x_b + x_b^2) / 3)`` with ``x = a - t, b - t``;
        * curve, span holding the whole support: the moments of the whole density about the
          support's centre (:meth:`_segment_tree`), as for whole segments below;
        * curve, otherwise: the (at most two) segments holding a and b by 2-point Gauss-Legendre on their
          part inside [a, b] (g is linear there, the integrand cubic: exact; every term >= 0), the
          whole segments between them from the moments of O(log m) segment-tree nodes
          (:meth:`_whole_segments`).  Inside [a, b] a whole segment's integrand averages at least
          h * (segment width) / 3 and is at most h^2, so the moment form loses at most about
          log10(12 m) digits.

        I > 0 wherever [a, b] overlaps the support with positive length; I = 0 where it does
        not (no photon time can be there).
        """
        t = np.asarray(t, dtype=np.float64)
        hw = np.asarray(half_width, dtype=np.float64)
        a = np.clip(t - hw, lo, hi)
        b = np.maximum(np.clip(t + hw, lo, hi), a)
        if self.is_box:
            xa, xb = a - t, b - t
            return (xb - xa) * np.maximum(hw * hw - (xa * xa + xa * xb + xb * xb) / 3.0, 0.0)
        uu = self._cdf_u
        first, last = self._seg_range                    # segments outside carry no mass: never visited
        c, m0, m1, m2 = self._segment_tree()[2]
        # Span holding the whole support: the moments of the whole density about the support's centre
        d = c - t
        out = np.maximum(hw * hw * m0 - (m2 + d * (2.0 * m1 + d * m0)), 0.0)
        part = np.flatnonzero((a > uu[first]) | (b < uu[last + 1]))
        if not part.size:
            return out
        a, b, t, hw = a[part], b[part], t[part], hw[part]
        ja = np.clip(np.searchsorted(uu, a, side="right") - 1, first, last)
        jb = np.maximum(np.clip(np.searchsorted(uu, b, side="left") - 1, first, last), ja)
        # The end segments, on their part inside [a, b]
        val = self._segment_gl2(ja, a, b, t, hw)
        two = np.flatnonzero(jb > ja)
        val[two] += self._segment_gl2(jb[two], a[two], b[two], t[two], hw[two])
        # The whole segments ja + 1 .. jb - 1 in between
        mid = np.flatnonzero(jb > ja + 1)
        if mid.size:
            val[mid] += self._whole_segments(ja[mid] + 1, jb[mid] - 1, t[mid], hw[mid])
        out[part] = val
        return out

    def _segment_gl2(self, j, a, b, t, hw) -> np.ndarray:
        """integral over segment j (n,) cut to [a, b] of (hw^2 - (tau - t)^2)+ g: 2-point Gauss-Legendre."""
        uu, w = self._cdf_u, self._w
        u0, u1 = uu[j], uu[j + 1]
        lo = np.maximum(a, u0)
        hi = np.maximum(np.minimum(b, u1), lo)
        half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
        w0, w1, width = w[j], w[j + 1], u1 - u0
        acc = np.zeros(np.shape(j))
        for tau in (mid - half * _GL2, mid + half * _GL2):
            f = np.clip((tau - u0) / width, 0.0, 1.0)               # lerp: g >= 0 under rounding
            d = np.abs(tau - t)
            acc += np.maximum((hw - d) * (hw + d), 0.0) * (w0 * (1.0 - f) + w1 * f)
        return acc * half / self._total

    def _whole_segments(self, j0, j1, t, hw) -> np.ndarray:
        """integral over the whole segments j0 .. j1 (n,) (all inside [t - hw, t + hw]) of (hw^2 - (tau - t)^2) g.

        The run is cut into the O(log m) nodes of a segment tree (:meth:`_segment_tree`); node
        ``v`` holds the moments ``M_k = integral of (tau - c_v)^k g`` about its centre c_v, so its part
        is ``hw^2 M_0 - (M_2 + 2 (c_v - t) M_1 + (c_v - t)^2 M_0)`` with |c_v - t| <= hw: no term
        exceeds 4 hw^2 M_0 (see :meth:`parabola_integral` for why that costs few digits).
        """
        (C, M0, M1, M2), size, _ = self._segment_tree()
        out = np.zeros(j0.shape[0])
        q = np.arange(j0.shape[0])                        # queries whose run is not used up yet
        lo, hi = j0 + size, j1 + 1 + size                 # half-open range of leaves, climbed level by level
        hw2 = hw * hw
        while q.size:
            for v in (np.where(lo & 1 == 1, lo, 0), np.where(hi & 1 == 1, hi - 1, 0)):
                m0, d = M0[v], C[v] - t                    # node 0 is empty (all 0): adds nothing
                out[q] += np.maximum(hw2 * m0 - (M2[v] + d * (2.0 * M1[v] + d * m0)), 0.0)
            lo, hi = (lo + 1) >> 1, hi >> 1
            live = lo < hi
            if not live.all():
                q, lo, hi, t, hw2 = q[live], lo[live], hi[live], t[live], hw2[live]
        return out

    def _segment_tree(self) -> tuple:
        """Moments of g per node of a segment tree over the curve's segments, built once and cached.

        Returns ((C, M0, M1, M2) each (2 size,), size, whole): node v (1 <= v < 2 size; leaves size + j for
        segment j, padding empty) covers a run of segments centred at C[v] (its knots' midpoint)
        and ``Mk[v] = integral over the run of (tau - C[v])^k g(tau) dtau`` (exact: 2-point
        Gauss-Legendre per segment; for k = 0, 2 a sum of terms >= 0).  Node 0 is all zeros.
        ``whole = (c, M0, M1, M2)``: the same for the whole density about the support's centre c.
        """
        if self._tree is not None:
            return self._tree
        uu, w = self._cdf_u, self._w
        nseg = uu.shape[0] - 1
        size = 1 << max(0, int(np.ceil(np.log2(nseg))))
        half, mid = 0.5 * np.diff(uu), 0.5 * (uu[1:] + uu[:-1])
        x = np.zeros((2, size))
        wt = np.zeros((2, size))
        x[:, :nseg] = [mid - half * _GL2, mid + half * _GL2]        # Gauss-Legendre nodes
        wt[:, :nseg] = half * np.interp(x[:, :nseg], uu, w) / self._total
        knots = np.concatenate([uu, np.full(size - nseg, uu[-1])])    # padding: empty segments at u = 1
        M = np.zeros((3, 2 * size))
        C = np.zeros(2 * size)
        width = 1
        while width <= size:                               # nodes of `width` segments: ids size/width + i
            first = size // width
            c = 0.5 * (knots[0:size:width] + knots[width:size + 1:width])             # (size / width,)
            d = x.reshape(2, first, width) - c[None, :, None]
            ww = wt.reshape(2, first, width)
            C[first:2 * first] = c
            for k in range(3):
                M[k, first:2 * first] = (ww * d ** k).sum(axis=(0, 2))
            width *= 2
        lo, hi = self.support
        c = 0.5 * (lo + hi)
        whole = (c,) + tuple(float((wt * (x - c) ** k).sum()) for k in range(3))
        self._tree = ((C, M[0], M[1], M[2]), size, whole)
        return self._tree
