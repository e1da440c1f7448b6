"""The film: named render passes and the pixel reconstruction filter.

One source of truth for the passes: :data:`PASSES` lists ``(name, channels,
channel_ids)`` and is used by the film, the EXR writer and the Blender add-on.

Pixel estimator (see docs/rendering.md)::

    I_j = sum_i w(x_i - c_j) L(x_i, t_i) / sum_i w(x_i - c_j)

``x_i`` is the film position of camera sample i (continuous pixel coordinates,
pixel j has centre ``c_j = (ix + 0.5, iy + 0.5)``), ``t_i`` its shutter time and
``w`` the separable Blackman-Harris filter.  Every sample is *splatted* to all
pixels its filter covers, so an edge that moves during the shutter produces a
smooth coverage ramp across pixel boundaries.
"""
from __future__ import annotations

import threading

import numpy as np
import scipy.sparse

from . import shading_kernels as _K

__all__ = ["PASSES", "PASS_NAMES", "pass_channels", "blackman_harris", "Film"]

# Render passes: (name, channel count, channel ids) -- Blender's names and order.
PASSES: tuple[tuple[str, int, str], ...] = (
    ("Combined", 4, "RGBA"),
    ("Depth", 1, "Z"),
    ("Normal", 3, "XYZ"),
    ("Emit", 3, "RGB"),
    ("Direct", 3, "RGB"),
    ("Indirect", 3, "RGB"),
    ("Caustic", 3, "RGB"),
)
PASS_NAMES: tuple[str, ...] = tuple(p[0] for p in PASSES)

# Depth written where a camera ray escapes (Blender writes 1e10 for the background).
DEPTH_BACKGROUND = 1.0e10


def pass_channels(name: str) -> int:
    """Channel count of the pass called ``name`` (KeyError if unknown)."""
    for n, c, _ in PASSES:
        if n == name:
            return c
    raise KeyError(name)


def blackman_harris(x: np.ndarray, radius: float) -> np.ndarray:
    """Blackman-Harris window of half-width ``radius`` pixels at offsets x (n,) -> (n,).

    w(x) = 0.35875 + 0.48829 cos(pi x / r) + 0.14128 cos(2 pi x / r) + 0.01168 cos(3 pi x / r)
    for |x| < r, 0 outside; w(0) = 1.  (The centred form of the usual
    0.35875 - 0.48829 cos(2 pi v) + ... with v = x / (2r) + 1/2.)
    """
    c = np.cos(np.pi * np.asarray(x, dtype=np.float64) / radius)
    # cos 2a = 2c^2 - 1, cos 3a = 4c^3 - 3c: one cosine per evaluation
    w = 0.35875 + 0.48829 * c + 0.14128 * (2 * c * c - 1) + 0.01168 * c * (4 * c * c - 3)
    return np.where(np.abs(x) < radius, w, 0.0)


def _blackman_harris32(x: np.ndarray, radius: float) -> np.ndarray:
    """:func:`blackman_harris` in float32 (x float32, any shape): the film's hot path.

    Float32 cosines are vectorised by numpy (several times faster than
    float64); the weights are stored in float32 anyway.  Written as a cubic in
    c = cos(pi x / r): (a0 - a2) + (a1 - 3 a3) c + 2 a2 c^2 + 4 a3 c^3.
    """
    c = np.cos(x * np.float32(np.pi / radius))
    c2 = c * c
    w = (np.float32(0.35875 - 0.14128) + np.float32(2 * 0.14128) * c2
         + c * (np.float32(0.48829 - 3 * 0.01168) + np.float32(4 * 0.01168) * c2))
    w[np.abs(x) >= np.float32(radius)] = 0.0
    return w


_WIN = threading.local()


def _window_buffer(shape: tuple) -> np.ndarray:
    """A zeroed float64 array of ``shape`` in this thread's reused buffer (valid until its next call)."""
    size = int(np.prod(shape))
    buf = getattr(_WIN, "buf", None)
    if buf is None or buf.size < size:
        buf = _WIN.buf = np.empty(size)
    out = buf[:size].reshape(shape)
    out[:] = 0.0
    return out


class Film:
    """Accumulates filter-weighted samples into the named passes.

    Parameters
    ----------
    width, height : image size in pixels.
    filter_width : Blackman-Harris width in pixels (``RenderSettings.filter_width``,
        Blender's default 1.5).  As in Cycles, the Blackman-Harris support is
        twice the width (radius = ``filter_width`` pixels), because the window is
        narrow near its ends.  ``filter_width == 0`` is a box over each pixel:
        a sample counts only for the pixel it falls in.

    Memory: float32 accumulators (H*W, 17) and the weight sum (H*W,)
    (72 bytes per pixel: 150 MB at 1920x1080).  Each batch is summed in
    float64 first and a pixel receives batches from at most a few tiles, so
    float32 storage loses nothing visible.
    """

    def __init__(self, width: int, height: int, filter_width: float = 1.5):
        self.width, self.height = int(width), int(height)
        self.radius = float(filter_width)
        self.n_channels = sum(c for _, c, _ in PASSES)
        self._sum = np.zeros((self.height * self.width, self.n_channels), np.float32)
        self._wsum = np.zeros(self.height * self.width, np.float32)

    def add_samples(self, px: np.ndarray, py: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """Splat samples at film positions px, py (n,) (pixels, row 0 = top).

        values : pass name -> (n, C) float array for every name in :data:`PASSES`.
        Work is done in the bounding box of the pixels the samples reach (a
        tile plus the filter margin), so the cost does not grow with the image.
        """
        px = np.asarray(px, dtype=np.float64)
        py = np.asarray(py, dtype=np.float64)
        n = px.shape[0]
        if n == 0:
            return
        V = np.concatenate([np.asarray(values[name], dtype=np.float64).reshape(n, c)
                            for name, c, _ in PASSES], axis=1)
        fx, fy = np.floor(px).astype(np.int64), np.floor(py).astype(np.int64)
        # Pixel offsets o (relative to the sample's own pixel) with |o + 1/2 - frac| < r
        r = self.radius
        offsets = range(int(np.floor(-0.5 - r)) + 1, int(np.ceil(0.5 + r))) if r > 0 else range(0, 1)
        m = max(-offsets[0], offsets[-1])
        # Local window: the samples' pixels plus the filter margin, clipped to the image
        x0, x1 = max(int(fx.min()) - m, 0), min(int(fx.max()) + m + 1, self.width)
        y0, y1 = max(int(fy.min()) - m, 0), min(int(fy.max()) + m + 1, self.height)
        if x0 >= x1 or y0 >= y1:
            return
        bw, bh = x1 - x0, y1 - y0
        # Separable weights: one window evaluation per offset and axis
        ones = np.ones(n)
        wxs = [ones if r <= 0 else blackman_harris(fx + o + 0.5 - px, r) for o in offsets]
        wys = [ones if r <= 0 else blackman_harris(fy + o + 0.5 - py, r) for o in offsets]
        C = self.n_channels
        # Each sample's K = len(offsets)^2 (window pixel, weight) pairs; pairs outside
        # the window keep weight 0 and point at pixel 0
        cols, vals = [], []
        for oy, wy in zip(offsets, wys):
            iy = fy + oy
            for ox, wx in zip(offsets, wxs):
                ix = fx + ox
                inside = (ix >= x0) & (ix < x1) & (iy >= y0) & (iy < y1)
                cols.append(np.where(inside, (iy - y0) * bw + (ix - x0), 0))
                vals.append(np.where(inside, wx * wy, 0.0))
        K = len(cols)
        # B (samples, window pixels) of filter weights, built directly in CSR form
        # (row i holds sample i's K entries); the sums are B^T @ [V, 1]
        B = scipy.sparse.csr_matrix((np.stack(vals, axis=1).ravel(), np.stack(cols, axis=1).ravel(),
                                     np.arange(0, n * K + 1, K)), shape=(n, bh * bw))
        sums = B.T @ np.concatenate([V, np.ones((n, 1))], axis=1)
        vsum, wsum = sums[:, :C], sums[:, C]
        # Add the window into the full-image accumulators
        S = self._sum.reshape(self.height, self.width, C)
        S[y0:y1, x0:x1] += vsum.reshape(bh, bw, C)
        Wt = self._wsum.reshape(self.height, self.width)
        Wt[y0:y1, x0:x1] += wsum.reshape(bh, bw)

    def _offsets(self) -> range:
        """Pixel offsets o (relative to a sample's own pixel) that its filter can reach."""
        r = self.radius
        return range(int(np.floor(-0.5 - r)) + 1, int(np.ceil(0.5 + r))) if r > 0 else range(0, 1)

    def add_tile(self, x0: int, y0: int, tw: int, th: int, px: np.ndarray, py: np.ndarray,
                 values: dict[str, np.ndarray]) -> None:
        """Splat the samples of one tile (same result as :meth:`add_samples`, faster).

        ``add_window(splat_tile(...))``: the splat itself touches no film state,
        so worker threads can run it and leave only the addition to the caller.
        """
        self.add_window(self.splat_tile(x0, y0, tw, th, px, py, values))

    def add_window(self, window) -> None:
        """Add a window returned by :meth:`splat_tile` into the accumulators."""
        if window is None:
            return
        (ya, yb, xa, xb), active, w = window
        C = self.n_channels
        k = w.shape[-1] - 1
        dst = self._sum.reshape(self.height, self.width, C)[ya:yb, xa:xb]
        j = 0
        for c0, c in active:
            dst[..., c0:c0 + c] += w[..., j:j + c]
            j += c
        self._wsum.reshape(self.height, self.width)[ya:yb, xa:xb] += w[..., k]

    def splat_tile(self, x0: int, y0: int, tw: int, th: int, px: np.ndarray, py: np.ndarray,
                   values: dict[str, np.ndarray]):
        """Filter-weighted sums of one tile's samples over the pixels they reach.

        Returns None (nothing to add) or ``((ya, yb, xa, xb), active, w)``: the
        image rows / columns the window covers, the (first channel, channels)
        of the passes it holds, and w (yb - ya, xb - xa, k + 1) float32 sums
        (last channel: the weight sum).  Reads only the film's size and filter.

        The samples must be laid out as :func:`stpm_core.integrator.camera_samples`
        makes them: the tile's pixels [x0, x0 + tw) x [y0, y0 + th) in row-major
        order, each pixel's S = n / (tw th) samples consecutive and inside that
        pixel.  Then every filter offset (ox, oy) sends pixel j's samples to one
        pixel, and the splat is one batched product per tile::

            sums[j, k, c] = sum_s w_k(x_js) V[j, s, c]     (k = filter offset)

        followed by K shifted block additions.  Passes that are all zero in the
        tile (e.g. Caustic without photons) are skipped.  Float32 throughout (each tile
        sums at most K * S products per pixel before it reaches the float32
        accumulators).
        """
        n = px.shape[0]
        P = tw * th
        if n == 0 or P == 0:
            return None
        if _K.AVAILABLE:
            V = np.concatenate([np.asarray(values[name], np.float64).reshape(n, c) for name, c, _ in PASSES], axis=1)
            return self.splat_tile_matrix(x0, y0, tw, th, px, py, V)
        S = n // P
        # Sample values (n, k + 1) float32 of the passes that are not all zero in this
        # tile (they add nothing); the last column counts the weight sum
        active, c0 = [], 0                       # (first image channel, channels, array)
        for name, c, _ in PASSES:
            a = np.asarray(values[name]).reshape(n, c)
            if np.any(a):
                active.append((c0, c, a))
            c0 += c
        k = sum(c for _, c, _ in active)
        V = np.empty((n, k + 1), np.float32)
        j = 0
        for _, c, a in active:
            V[:, j:j + c] = a
            j += c
        V[:, k] = 1.0
        # Separable filter weights per offset: (n, k) along x and y
        offsets = self._offsets()
        r = self.radius
        if r > 0:
            px = np.asarray(px, np.float64)
            py = np.asarray(py, np.float64)
            o = np.asarray(offsets, np.float32) + np.float32(0.5)
            wx = _blackman_harris32((np.floor(px) - px).astype(np.float32)[:, None] + o[None, :], r)
            wy = _blackman_harris32((np.floor(py) - py).astype(np.float32)[:, None] + o[None, :], r)
        else:
            wx = wy = np.ones((n, 1), np.float32)
        k1 = len(offsets)
        Wk = (wy[:, :, None] * wx[:, None, :]).reshape(P, S, k1 * k1)   # offset k = (iy, ix)
        sums = np.matmul(Wk.transpose(0, 2, 1), V.reshape(P, S, k + 1))  # (P, K, k + 1)
        sums = sums.reshape(th, tw, k1 * k1, k + 1)
        # Shifted block additions into a local window (the tile plus the filter margin)
        lo, hi = offsets[0], offsets[-1]
        win = np.zeros((th + hi - lo, tw + hi - lo, k + 1), np.float32)
        for iy in range(k1):
            for ix in range(k1):
                win[iy:iy + th, ix:ix + tw] += sums[:, :, iy * k1 + ix]
        # The window, clipped to the image, into the accumulators (active passes only)
        ya, yb = max(y0 + lo, 0), min(y0 + hi + th, self.height)
        xa, xb = max(x0 + lo, 0), min(x0 + hi + tw, self.width)
        if ya >= yb or xa >= xb:
            return None
        w = win[ya - y0 - lo:yb - y0 - lo, xa - x0 - lo:xb - x0 - lo]
        return (ya, yb, xa, xb), [(c0, c) for c0, c, _ in active], w

    def splat_tile_matrix(self, x0: int, y0: int, tw: int, th: int, px: np.ndarray, py: np.ndarray,
                          V: np.ndarray, combined_is_sum: bool = False, alpha_one: bool = False,
                          zero: tuple = (), scan: bool = True, channels: np.ndarray | None = None,
                          columns: np.ndarray | None = None):
        """:meth:`splat_tile` with the sample values as one matrix V (n, m) float64, by the
        compiled kernel ``shading_kernels.splat_tile`` (float32 per-pixel sums as in the
        numpy splat, float64 window).  Needs ``shading_kernels.AVAILABLE``.

        channels (m,): the image channel (:data:`PASSES` order, 0 .. 19) of
        each column of V; None = V has all 20 channels in order.  columns: the
        columns to sum (None: all; with ``scan`` the all-zero ones are then
        skipped, ``zero`` names passes known to be 0).  The splat is linear in
        V, so channels that are fixed combinations of others need no sums of
        their own: ``combined_is_sum`` (Combined RGB = Emit + Direct + Indirect
        + Caustic for every sample, as the integrator makes it) and
        ``alpha_one`` (Combined alpha = 1: its sum is the weight sum) take them
        from the other sums.  Returns the :meth:`splat_tile` window format
        with every pass.
        """
        n = px.shape[0]
        P = tw * th
        if n == 0 or P == 0:
            return None
        C = self.n_channels
        V = np.ascontiguousarray(V, np.float64)
        chan = np.arange(C) if channels is None else np.asarray(channels, np.int64)
        if columns is None:
            skip = np.zeros(V.shape[1], bool)
            skip |= (chan < 3) if combined_is_sum else False
            skip |= (chan == 3) if alpha_one else False
            for name in zero:
                c0 = self._first_channel(name)
                skip |= (chan >= c0) & (chan < c0 + pass_channels(name))
            act = _K.active_channels(V, skip) if scan else np.flatnonzero(~skip)
        else:
            act = np.asarray(columns, np.int64)
        offsets = self._offsets()
        lo, k1 = offsets[0], len(offsets)
        win = _window_buffer((th + k1 - 1, tw + k1 - 1, act.size + 1))
        _K.splat_tile(tw, th, n // P, np.ascontiguousarray(px, np.float64), np.ascontiguousarray(py, np.float64),
                      V, act, self.radius, lo, k1, win)
        ya, yb = max(y0 + lo, 0), min(y0 + lo + th + k1 - 1, self.height)
        xa, xb = max(x0 + lo, 0), min(x0 + lo + tw + k1 - 1, self.width)
        if ya >= yb or xa >= xb:
            return None
        # Image channels: the sums, Combined RGB from its parts (in Emit, Direct, Indirect,
        # Caustic order, float64), Combined alpha from the weight sum
        summed = chan[act]
        comb = np.array([int(np.flatnonzero(summed == c0)[0]) for c0 in
                         (self._first_channel(name) for name in ("Emit", "Direct", "Indirect", "Caustic"))
                         if combined_is_sum and np.any(summed == c0)], np.int64)
        w = np.empty((yb - ya, xb - xa, C + 1), np.float32)
        _K.splat_finish(win, ya - y0 - lo, yb - y0 - lo, xa - x0 - lo, xb - x0 - lo, np.ascontiguousarray(summed),
                        comb, bool(alpha_one), w)
        return (ya, yb, xa, xb), [(0, C)], w

    @staticmethod
    def _first_channel(name: str) -> int:
        """First image channel of pass ``name`` in :data:`PASSES` order."""
        c0 = 0
        for n, c, _ in PASSES:
            if n == name:
                return c0
            c0 += c
        raise KeyError(name)

    def resolve(self) -> dict[str, np.ndarray]:
        """The passes as name -> (H, W, C) float32: weighted sums over weight sums.

        A pixel that no sample reached (only possible with a very narrow filter)
        is 0, with Depth = :data:`DEPTH_BACKGROUND`.
        """
        w = self._wsum[:, None]
        img = np.where(w > 0, self._sum / np.where(w > 0, w, 1.0), 0.0)
        out, c0 = {}, 0
        for name, c, _ in PASSES:
            a = img[:, c0:c0 + c].reshape(self.height, self.width, c)
            if name == "Depth":
                a = np.where(w.reshape(self.height, self.width, 1) > 0, a, DEPTH_BACKGROUND)
            out[name] = a.astype(np.float32)
            c0 += c
        return out
