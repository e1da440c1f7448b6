"""Adaptive sampling: Cycles' Noise Threshold (``use_adaptive_sampling``, ``adaptive_threshold``,
``adaptive_min_samples``), pixel by pixel.

The image is traced in rounds (:func:`schedule`): every pixel takes the first ``n_min`` samples,
then rounds of :data:`ADAPTIVE_STEP` samples go only to the pixels that still need them.  After each
round, pixel j's error is estimated from two means of its own samples (Cycles'
``film_adaptive_sampling_convergence_check``; Dammertz et al., "A hierarchical automatic stopping
condition for Monte Carlo global illumination", 2.1)::

    I_j = sum over all N_j samples of Combined RGB            (Film's Combined sums)
    A_j = 2 * sum over the samples of odd index               (``half``: an estimate of I_j from half)
    e_j = sum_c |I_jc - A_jc| / N_j / (1e-4 + g(sum_c I_jc / N_j)),   g(v) = sqrt(v) (v < 1), v (v >= 1)

and pixel j converged when ``e_j < THRESHOLD_SCALE * adaptive_threshold``.  The unconverged set is
dilated by one pixel in x, then in y (a 3 x 3 box, Cycles' ``filter_x`` / ``filter_y``): a pixel next
to an unconverged one keeps (or resumes) sampling.  Beyond Cycles, a pixel also keeps sampling while
a pixel within ``OUTLIER_RADIUS`` of it (a 7 x 7 box) has ``e >= OUTLIER_FACTOR * THRESHOLD_SCALE *
adaptive_threshold``: where a neighbour drew a rare bright path, a pixel whose own samples agree may
just not have drawn it yet (stopping it reads the region low: docs/rendering.md, "Adaptive sampling").  A pixel's value stays the mean of its own
samples (filter importance sampling: its samples count for it alone), so the image is unbiased up to
the stopping rule's small correlation between a pixel's sample count and its samples (as in Cycles).

These are image-level array operations (a few per round), not shading: numpy is enough.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["ADAPTIVE_STEP", "THRESHOLD_SCALE", "OUTLIER_RADIUS", "OUTLIER_FACTOR", "min_samples", "schedule", "pixel_error", "need_samples"]

#: Samples per round after the first (Cycles' ``adaptive_step`` is 16).  64 here: a pixel's samples
#: in one batch share photon-map estimates (``photons.sharing``), so a round of 16 costs more per
#: sample than one of 64 -- on the product shot at 160 x 120 (threshold 0.03, min 32) rounds of 16
#: made 1.40 estimates per camera sample and took 0.60 CPU-s per mean sample per pixel, rounds of 64
#: 0.72 and 0.41, the fixed 64-sample render 0.37 and 0.36 (docs/rendering.md, "Adaptive sampling")
ADAPTIVE_STEP = 64
#: Cycles scales the artist's threshold by 5 ("makes the threshold more similar to what it was before")
THRESHOLD_SCALE = 5.0
#: A pixel keeps sampling while a pixel within this many pixels (x and y: a (2 r + 1)^2 box) has an
#: error of at least OUTLIER_FACTOR times the threshold: the rare-bright-path guard (docs/rendering.md,
#: "Adaptive sampling").  On the product shot's caustic region (offline replay of the recorded rounds,
#: seeds 0 and 1, threshold 0.05, 32-256 samples) Cycles' rule alone read the region's mean 0.80, with
#: this guard (r 3, factor 2) 0.945 for 1.17 x the pixels in the second round; a plain 5 x 5 or 7 x 7 max
#: of e read 0.90 / 0.98 for 1.8 x / 2.3 x them
OUTLIER_RADIUS = 3
OUTLIER_FACTOR = 2.0


def min_samples(threshold: float, adaptive_min_samples: int) -> int:
    """The samples every pixel takes before its first check, as Cycles: ``adaptive_min_samples``, or
    for 0 (automatic) ceil(16 / threshold^0.3) (threshold 0.1 -> 32, 0.01 -> 64, 0.001 -> 128); at
    least 4."""
    if adaptive_min_samples > 0:
        return max(4, int(adaptive_min_samples))
    if threshold <= 0.0:
        return 4
    return max(4, int(math.ceil(16.0 / threshold ** 0.3)))


def schedule(samples: int, n_min: int, step: int = ADAPTIVE_STEP) -> list[tuple[int, int]]:
    """Rounds as (first sample index, samples per pixel): (0, min(n_min, samples)), then rounds of
    ``step`` (the last one shorter) until ``samples``.  A round's samples have the pixel's sample
    indices first .. first + count - 1 whatever pixels take part."""
    out, s = [], min(int(n_min), int(samples))
    out.append((0, s))
    while s < samples:
        b = min(step, samples - s)
        out.append((s, b))
        s += b
    return out


def pixel_error(I: np.ndarray, A: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Cycles' per-pixel error e (...,) from the Combined RGB sums I (..., 3), the doubled odd-sample
    sums A (..., 3) and the sample counts N (...,) (pixels with N = 0: infinite)."""
    N = np.asarray(N, np.float64)
    inv = np.where(N > 0, 1.0 / np.maximum(N, 1.0), 0.0)
    diff = np.abs(np.asarray(I, np.float64) - A).sum(axis=-1) * inv
    v = np.asarray(I, np.float64).sum(axis=-1) * inv
    norm = np.where(v < 1.0, np.sqrt(np.maximum(v, 0.0)), v)
    e = diff / (1e-4 + norm)
    return np.where(N > 0, e, np.inf)


def _box_any(u: np.ndarray, r: int) -> np.ndarray:
    """(H, W) bool: u dilated by r pixels along x, then along y (a (2 r + 1)^2 box)."""
    x = u.copy()
    for d in range(1, r + 1):
        x[:, d:] |= u[:, :-d]
        x[:, :-d] |= u[:, d:]
    y = x.copy()
    for d in range(1, r + 1):
        y[d:, :] |= x[:-d, :]
        y[:-d, :] |= x[d:, :]
    return y


def need_samples(err: np.ndarray, threshold: float) -> np.ndarray:
    """(H, W) bool: the pixels that take the next round, from the errors e (H, W): e >= THRESHOLD_SCALE *
    threshold dilated by one pixel along x then along y (a 3 x 3 box, Cycles), or a pixel within
    OUTLIER_RADIUS (a 7 x 7 box) with e >= OUTLIER_FACTOR * THRESHOLD_SCALE * threshold."""
    t = THRESHOLD_SCALE * float(threshold)
    err = np.asarray(err)
    return _box_any(err >= t, 1) | _box_any(err >= OUTLIER_FACTOR * t, OUTLIER_RADIUS)
