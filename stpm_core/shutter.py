"""The camera shutter: when it is open, and how exposure is weighted in time.

Normalised shutter time ``u`` in [0, 1] maps to frames as
``frame = open + u * (close - open)``.  Blender's shutter curve (a weight over
the open interval, default flat) is the density of ``u``; camera samples and
photon paths both draw their time from it by its inverse CDF, so the pixel
value is the curve-weighted time average of radiance (see docs/time.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError

__all__ = ["Shutter"]


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
        linear in between (Blender's ``motion_blur_shutter_curve`` sampled).
        ``None`` is a box: every instant weighs the same.
    """

    open: float = 1.0
    close: float = 1.0
    curve: np.ndarray | None = None
    _cdf_u: np.ndarray = field(init=False, repr=False)
    _cdf: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.open) and np.isfinite(self.close)):
            raise SceneError("shutter.open/close must be finite")
        if self.close < self.open:
            raise SceneError(f"shutter closes ({self.close}) before it opens ({self.open})")
        if self.curve is not None:
            c = np.asarray(self.curve, dtype=np.float64).ravel()
            if c.shape[0] < 2 or not np.all(np.isfinite(c)) or np.any(c < 0) or c.sum() <= 0:
                raise SceneError("shutter.curve must have >= 2 finite non-negative weights, not all zero")
            self.curve = c
            u = np.linspace(0.0, 1.0, c.shape[0])
            seg = 0.5 * (c[1:] + c[:-1]) * np.diff(u)
            cdf = np.concatenate([[0.0], np.cumsum(seg)])
            self._cdf_u, self._cdf = u, cdf / cdf[-1]

    @property
    def length(self) -> float:
        """Shutter length in frames."""
        return float(self.close - self.open)

    @property
    def is_instant(self) -> bool:
        """True when the shutter has (numerically) zero length: no motion blur."""
        return self.length <= 0.0

    def to_frame(self, u: np.ndarray) -> np.ndarray:
        """Normalised time (n,) -> frame number (n,)."""
        return self.open + np.asarray(u) * (self.close - self.open)

    def sample(self, xi: np.ndarray) -> np.ndarray:
        """Map uniform numbers xi (n,) in [0, 1) to shutter times u (n,) with the curve's density.

        Stratified ``xi`` stays stratified (the map is monotone).  For a box
        shutter this is the identity; for a zero-length shutter it returns 0.5.
        """
        xi = np.asarray(xi, dtype=np.float64)
        if self.is_instant:
            return np.full(xi.shape, 0.5)
        if self.curve is None:
            return xi.copy()
        # Invert the piecewise-quadratic CDF of a piecewise-linear density.
        i = np.clip(np.searchsorted(self._cdf, xi, side="right") - 1, 0, len(self._cdf) - 2)
        u0, u1 = self._cdf_u[i], self._cdf_u[i + 1]
        c0, c1 = self.curve[i], self.curve[i + 1]
        h = u1 - u0
        total = 0.5 * (self.curve[1:] + self.curve[:-1]) @ np.diff(self._cdf_u)
        target = (xi - self._cdf[i]) * total  # area to cover inside the segment
        slope = (c1 - c0) / h
        # Solve c0*x + slope*x^2/2 = target for x in [0, h].
        lin = np.abs(slope) < 1e-12
        disc = np.maximum(c0 * c0 + 2 * slope * target, 0.0)
        x_quad = (-c0 + np.sqrt(disc)) / np.where(lin, 1.0, slope)
        x_lin = target / np.maximum(c0, 1e-300)
        x = np.clip(np.where(lin, x_lin, x_quad), 0.0, h)
        return u0 + x

    def density(self, u: np.ndarray) -> np.ndarray:
        """Probability density of shutter time at u (n,); integrates to 1 over [0, 1]."""
        u = np.asarray(u, dtype=np.float64)
        if self.curve is None:
            return np.ones_like(u)
        total = 0.5 * (self.curve[1:] + self.curve[:-1]) @ np.diff(self._cdf_u)
        return np.interp(u, self._cdf_u, self.curve) / total
