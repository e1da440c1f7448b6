"""Error of a render against a reference: RMSE, relative MSE, FLIP, and error-map images.

Every metric is taken over the linear RGB of the ``Combined`` pass, both
images (H, W, 3) float, row 0 = top:

* ``rmse``   = sqrt( mean over pixels and channels of (x - r)^2 )
  (same unit as the pixels: shutter-averaged radiance, W m^-2 sr^-1);
* ``relmse`` = mean of (x - r)^2 / (r^2 + eps), eps = :data:`RELMSE_EPS`
  (unitless; the eps keeps black pixels from dominating);
* ``flip``   = mean HDR-FLIP error (NVIDIA's perceptual metric, the
  ``flip-evaluator`` package), in [0, 1]; the exposure range is chosen by
  FLIP from the reference alone, so every run is judged with the same one.

Non-finite pixels are counted as 0 (the renderer never writes them; a
supplied reference might).  A metric that cannot be computed is ``None``.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["RELMSE_EPS", "combined_rgb", "rmse", "relmse", "flip_error", "image_errors",
           "signed_relative_error", "diverging_colors", "display_scale"]

RELMSE_EPS = 1e-2          # relative MSE denominator guard (radiance^2)
_LUMA = np.array([0.2126, 0.7152, 0.0722])   # Rec. 709 luminance weights


def combined_rgb(passes_or_rgb) -> np.ndarray:
    """Linear RGB (H, W, 3) float64 from a passes dict (its ``Combined``) or an (H, W, >=3) array."""
    a = passes_or_rgb["Combined"] if isinstance(passes_or_rgb, dict) else passes_or_rgb
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] < 3:
        raise ValueError(f"expected an (H, W, 3|4) image, got shape {a.shape}")
    return np.nan_to_num(a[:, :, :3], nan=0.0, posinf=0.0, neginf=0.0)


def rmse(x: np.ndarray, r: np.ndarray) -> float:
    """Root-mean-square error over pixels and channels (pixel units)."""
    return float(np.sqrt(np.mean((x - r) ** 2)))


def relmse(x: np.ndarray, r: np.ndarray, eps: float = RELMSE_EPS) -> float:
    """Relative MSE: mean of (x - r)^2 / (r^2 + eps) over pixels and channels (unitless)."""
    return float(np.mean((x - r) ** 2 / (r ** 2 + eps)))


def flip_error(x: np.ndarray, r: np.ndarray) -> tuple[float | None, np.ndarray | None]:
    """(mean HDR-FLIP error, magma false-colour error map (H, W, 3) in [0, 1]) or (None, None).

    FLIP needs a reference with some light in it (its exposure range comes
    from the reference's luminance); an all-black reference gives (None, None),
    and so does a platform without the flip-evaluator wheel (macOS x86_64).
    """
    if not np.any(r > 0):
        return None, None
    try:
        import flip_evaluator as flip
    except ImportError:  # no wheel for this platform (macOS x86_64): RMSE and relMSE still stand
        return None, None

    ref = np.ascontiguousarray(np.maximum(r, 0.0), dtype=np.float32)
    test = np.ascontiguousarray(np.maximum(x, 0.0), dtype=np.float32)
    error_map, mean, _params = flip.evaluate(ref, test, "HDR", applyMagma=True)
    mean = float(mean)
    if not math.isfinite(mean):
        return None, None
    return mean, np.clip(np.asarray(error_map, dtype=np.float64).reshape(r.shape[0], r.shape[1], -1)[:, :, :3],
                         0.0, 1.0)


def image_errors(x: np.ndarray, r: np.ndarray, *, with_flip: bool = True) -> dict:
    """All metrics of test ``x`` against reference ``r`` (both (H, W, 3) linear RGB).

    Returns {'rmse', 'relmse', 'flip'} (floats or None) and '_flip_map' (H, W, 3) or None.
    """
    if x.shape != r.shape:
        raise ValueError(f"image {x.shape} and reference {r.shape} differ in size")
    out = {"rmse": rmse(x, r), "relmse": relmse(x, r), "flip": None, "_flip_map": None}
    if with_flip:
        out["flip"], out["_flip_map"] = flip_error(x, r)
    for key in ("rmse", "relmse", "flip"):
        if out[key] is not None and not math.isfinite(out[key]):
            out[key] = None
    return out


# ----------------------------------------------------------------------------
# Images for the report
# ----------------------------------------------------------------------------
def signed_relative_error(x: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(H, W) luminance error relative to the reference: (Y_x - Y_r) / max(Y_r, floor).

    Negative = too dark, positive = too bright; floor = 5 % of the reference's
    mean luminance (so black pixels do not blow up).
    """
    Yx, Yr = x @ _LUMA, r @ _LUMA
    floor = max(0.05 * float(Yr.mean()), 1e-6)
    return (Yx - Yr) / np.maximum(Yr, floor)


def diverging_colors(v: np.ndarray, limit: float = 0.5) -> np.ndarray:
    """Blue - white - red false colour (H, W, 3) in [0, 1] for values (H, W) in [-limit, limit].

    Blue = too dark, white = right, red = too bright (display values, not linear).
    """
    s = np.clip(np.nan_to_num(v) / limit, -1.0, 1.0)[..., None]
    white = np.ones(3)
    blue, red = np.array([0.13, 0.35, 0.85]), np.array([0.85, 0.13, 0.13])
    return np.where(s < 0, white + (-s) * (blue - white), white + s * (red - white))


def display_scale(r: np.ndarray) -> float:
    """Exposure multiplier shared by every image of a report: maps the reference's
    99th-percentile luminance to 1 when it is brighter than that, else 1."""
    Y = r @ _LUMA
    p99 = float(np.percentile(Y, 99)) if Y.size else 0.0
    return 1.0 / p99 if p99 > 1.0 else 1.0
