"""The film: named render passes and the pixel reconstruction filter.

One source of truth for the passes: :data:`PASSES` lists ``(name, channels,
channel_ids)`` and is used by the film, the EXR writer and the Blender add-on; with
``RenderSettings.denoise`` a render adds :data:`DENOISING_PASSES` (:func:`passes_for`).

Pixel estimator (see docs/rendering.md, "The pixel estimator")::

    I_j = (1 / S) sum_{i in pixel j} L(x_i, t_i),    x_i - c_j ~ w / (integral of w)

Filter importance sampling, as Cycles and pbrt-v4 do: camera sample i of
pixel j sits at ``x_i = c_j + filter_offsets(u_i, r)`` (``c_j = (ix + 0.5, iy +
0.5)``, ``u_i`` the pixel's stratified uniforms), drawn from the normalised
separable Blackman-Harris window ``w``, and counts for pixel j only, with
weight 1.  The expected value is the filter-weighted average
``integral w(x - c_j) L(x, t) dx / integral w``, the same as splatting each
sample into every pixel its filter covers, but each sample is added once
instead of (2r + 1)^2 times.  A moving edge still gives a smooth coverage
ramp: neighbouring pixels' samples overlap on the film.
"""
from __future__ import annotations

import threading

import numpy as np

from .kernels import paths as _K

__all__ = ["PASSES", "PASS_NAMES", "DENOISING_GUIDES", "DENOISING_PASSES", "ADAPTIVE_PASSES", "ALL_PASSES", "passes_for",
           "pass_channels", "blackman_harris", "filter_offsets", "BH_INVERSE_CDF", "Film"]

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
# With RenderSettings.denoise: Cycles' guide passes for a denoiser (summed by the film like the
# others; kernels.paths.denoising_rows) and, under Cycles' name, the raw Combined (a copy), kept
# beside the denoised image that Blender's Denoise node makes from the three.
DENOISING_GUIDES: tuple[tuple[str, int, str], ...] = (
    ("Denoising Albedo", 3, "RGB"),
    ("Denoising Normal", 3, "XYZ"),
)
DENOISING_PASSES: tuple[tuple[str, int, str], ...] = DENOISING_GUIDES + (("Noisy Image", 4, "RGBA"),)
# With adaptive sampling (RenderSettings.use_adaptive_sampling): each pixel's samples (as Cycles'
# Sample Count debug pass; integrator._trace_adaptive)
ADAPTIVE_PASSES: tuple[tuple[str, int, str], ...] = (("Sample Count", 1, "X"),)
# Every pass STPM can write, in the order it writes them
ALL_PASSES: tuple[tuple[str, int, str], ...] = PASSES + DENOISING_PASSES + ADAPTIVE_PASSES


def passes_for(denoise: bool = False, adaptive: bool = False) -> tuple:
    """The passes a render writes: :data:`PASSES`, plus :data:`DENOISING_PASSES` with ``denoise``,
    plus :data:`ADAPTIVE_PASSES` with ``adaptive`` (a render that sampled adaptively)."""
    return PASSES + (DENOISING_PASSES if denoise else ()) + (ADAPTIVE_PASSES if adaptive else ())

# Depth written where a camera ray escapes (Blender writes 1e10 for the background).
DEPTH_BACKGROUND = 1.0e10

# Blackman-Harris coefficients: w(x) = A0 + A1 cos(pi x / r) + A2 cos(2 pi x / r) + A3 cos(3 pi x / r)
BH_A = (0.35875, 0.48829, 0.14128, 0.01168)


def pass_channels(name: str) -> int:
    """Channel count of the pass called ``name`` (KeyError if unknown)."""
    for n, c, _ in ALL_PASSES:
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


def blackman_harris_cdf(v: np.ndarray) -> np.ndarray:
    """CDF of the unit-radius window on [-1, 1]: F(v) = integral_{-1}^{v} w / integral_{-1}^{1} w.

    integral_{-1}^{v} w = A0 (v + 1) + sum_k A_k sin(k pi v) / (k pi)   (the sines vanish at -1),
    and the whole integral is 2 A0.
    """
    v = np.clip(np.asarray(v, dtype=np.float64), -1.0, 1.0)
    a0, a1, a2, a3 = BH_A
    s = a0 * (v + 1.0) + sum(a * np.sin(k * np.pi * v) / (k * np.pi) for k, a in ((1, a1), (2, a2), (3, a3)))
    return s / (2.0 * a0)


def _inverse_cdf_table(m: int = 4097, fine: int = 1 << 17) -> np.ndarray:
    """(m,) float64: F^-1(j / (m - 1)) of the unit-radius window (-1 .. 1), by inverting F on a fine grid."""
    v = np.linspace(-1.0, 1.0, fine + 1)
    return np.interp(np.linspace(0.0, 1.0, m), blackman_harris_cdf(v), v)


# Inverse CDF of the unit-radius Blackman-Harris window at m = 4097 evenly spaced
# probabilities (linear in between: filter_offsets, kernels.paths.camera_tile).
BH_INVERSE_CDF: np.ndarray = _inverse_cdf_table()


def filter_offsets(u: np.ndarray, radius: float) -> np.ndarray:
    """Film offsets (pixels, from the pixel centre) distributed as the window: u (n,) in [0, 1) -> (n,).

    ``radius * F^-1(u)`` with F^-1 interpolated linearly in :data:`BH_INVERSE_CDF`
    (the same formula as the compiled ``camera_tile``).  ``radius <= 0``: the box
    filter, offsets ``u - 1/2`` (uniform over the pixel).
    """
    u = np.asarray(u, dtype=np.float64)
    if radius <= 0:
        return u - 0.5
    T = BH_INVERSE_CDF
    s = u * (T.size - 1)
    j = np.minimum(s.astype(np.int64), T.size - 2)
    f = s - j
    return radius * (T[j] * (1.0 - f) + T[j + 1] * f)


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
    """Accumulates camera samples into the named passes, each sample into its own pixel.

    Parameters
    ----------
    width, height : image size in pixels.
    passes : the passes summed, (name, channels, ids) in channel order (:data:`PASSES`; with
        denoising, PASSES + :data:`DENOISING_GUIDES`).
    filter_width : Blackman-Harris width in pixels (``RenderSettings.filter_width``,
        Blender's default 1.5).  As in Cycles, the Blackman-Harris support is
        twice the width (radius = ``filter_width`` pixels), because the window is
        narrow near its ends.  The filter shapes where camera samples are placed
        (:func:`filter_offsets`); the film itself only sums.  ``filter_width == 0``
        is a box over each pixel.

    Memory: float32 accumulators (H*W, 20) and the sample count (H*W,)
    (84 bytes per pixel: 175 MB at 1920x1080).  Each tile is summed in float64
    and a pixel receives one tile, so float32 storage loses nothing visible.
    """

    def __init__(self, width: int, height: int, filter_width: float = 1.5, passes: tuple = PASSES):
        self.width, self.height = int(width), int(height)
        self.radius = float(filter_width)
        self.passes = tuple(passes)             # PASSES, or PASSES + DENOISING_GUIDES
        self.n_channels = sum(c for _, c, _ in self.passes)
        self._sum = np.zeros((self.height * self.width, self.n_channels), np.float32)
        self._wsum = np.zeros(self.height * self.width, np.float32)

    def add_samples(self, ix: np.ndarray, iy: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """Add samples to the pixels they were drawn for: ix, iy (n,) integer pixel indices (row 0 = top).

        values : pass name -> (n, C) float array for every name in :data:`PASSES`.
        The general (slow) form of :meth:`tile_sums` + :meth:`add_window`.
        """
        ix = np.asarray(ix, dtype=np.int64)
        iy = np.asarray(iy, dtype=np.int64)
        n = ix.shape[0]
        if n == 0:
            return
        V = np.concatenate([np.asarray(values[name], dtype=np.float64).reshape(n, c)
                            for name, c, _ in self.passes], axis=1)
        j = iy * self.width + ix
        acc = np.zeros((self.height * self.width, self.n_channels + 1))
        np.add.at(acc, j, np.concatenate([V, np.ones((n, 1))], axis=1))
        self._sum += acc[:, :-1].astype(np.float32)
        self._wsum += acc[:, -1].astype(np.float32)

    def add_window(self, window) -> None:
        """Add a window returned by :meth:`tile_sums` into the accumulators."""
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

    def tile_sums(self, x0: int, y0: int, tw: int, th: int, values: dict[str, np.ndarray]):
        """Per-pixel sums of one tile's samples (touches no film state: worker threads run it).

        Returns None (nothing to add) or ``((ya, yb, xa, xb), active, w)``: the
        image rows / columns of the tile, the (first channel, channels) of the
        passes it holds, and w (yb - ya, xb - xa, k + 1) float32 sums (last
        channel: the sample count), for :meth:`add_window`.

        The samples must be laid out as the integrator's tiles
        (``kernels.paths.camera_tile``) make them: the tile's pixels [x0, x0 + tw) x [y0, y0 + th) in row-major
        order, each pixel's S = n / (tw th) samples consecutive, so
        ``w[p, c] = sum_s V[p, s, c]``.  Passes that are all zero in the tile
        (e.g. Caustic without photons) are skipped.  Sums in float64.
        """
        P = tw * th
        n = next(iter(values.values())).shape[0] if values else 0
        if n == 0 or P == 0:
            return None
        V = np.concatenate([np.asarray(values[name], np.float64).reshape(n, c) for name, c, _ in self.passes], axis=1)
        return self.tile_sums_matrix(x0, y0, tw, th, V)

    def tile_sums_matrix(self, x0: int, y0: int, tw: int, th: int, V: np.ndarray, combined_is_sum: bool = False,
                         alpha_one: bool = False, zero: tuple = (), scan: bool = True,
                         channels: np.ndarray | None = None, columns: np.ndarray | None = None):
        """:meth:`tile_sums` with the sample values as one matrix V (n, m) float64, by the
        compiled kernels ``kernels.paths.pixel_sums`` and ``tile_finish`` (float64
        sums).

        channels (m,): the image channel (:data:`PASSES` order, 0 .. 19) of
        each column of V; None = V has all 20 channels in order.  columns: the
        columns to sum (None: all; with ``scan`` the all-zero ones are then
        skipped, ``zero`` names passes known to be 0).  The sums are linear in
        V, so channels that are fixed combinations of others need no sums of
        their own: ``combined_is_sum`` (Combined RGB = Emit + Direct + Indirect
        + Caustic for every sample, as the integrator makes it) and
        ``alpha_one`` (Combined alpha = 1: its sum is the sample count) take them
        from the other sums.  Returns the :meth:`tile_sums` window format
        with every pass.
        """
        n = V.shape[0]
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
        win = _window_buffer((th, tw, act.size + 1))
        _K.pixel_sums(tw, th, n // P, V, act, win)
        yb, xb = min(y0 + th, self.height), min(x0 + tw, self.width)
        # Image channels: the sums, Combined RGB from its parts (in Emit, Direct, Indirect,
        # Caustic order, float64), Combined alpha from the sample count
        summed = chan[act]
        comb = self._combined_columns(summed, combined_is_sum)
        w = np.empty((yb - y0, xb - x0, C + 1), np.float32)
        _K.tile_finish(win, 0, yb - y0, 0, xb - x0, np.ascontiguousarray(summed), comb, bool(alpha_one), w)
        return (y0, yb, x0, xb), [(0, C)], w

    def _combined_columns(self, summed: np.ndarray, combined_is_sum: bool) -> np.ndarray:
        """Positions in summed (the image channels summed) of the first channel of Emit, Direct,
        Indirect and Caustic (those summed), whose sums add up to Combined RGB (``tile_finish``)."""
        return np.array([int(np.flatnonzero(summed == c0)[0]) for c0 in
                         (self._first_channel(name) for name in ("Emit", "Direct", "Indirect", "Caustic"))
                         if combined_is_sum and np.any(summed == c0)], np.int64)

    def pixel_sums_matrix(self, S: int, V: np.ndarray, channels: np.ndarray, columns: np.ndarray,
                          alpha_one: bool = False) -> np.ndarray:
        """Sums of the samples of k = n / S pixels anywhere in the image (adaptive sampling's rounds):
        V (n, m) float64, each pixel's S samples consecutive; channels (m,) each column's image
        channel, columns the columns to sum; Combined RGB from its parts (``combined_is_sum`` of
        :meth:`tile_sums_matrix`), alpha from the count with alpha_one.  Returns (k, C + 1) float32
        (last column: the sample count) for :meth:`add_pixels`.  Touches no film state."""
        k = V.shape[0] // int(S)
        C = self.n_channels
        chan = np.asarray(channels, np.int64)
        act = np.asarray(columns, np.int64)
        win = _window_buffer((1, k, act.size + 1))
        _K.pixel_sums(k, 1, int(S), np.ascontiguousarray(V, np.float64), act, win)
        summed = np.ascontiguousarray(chan[act])
        w = np.empty((1, k, C + 1), np.float32)
        _K.tile_finish(win, 0, 1, 0, k, summed, self._combined_columns(summed, True), bool(alpha_one), w)
        return w[0]

    def add_pixels(self, pixels: np.ndarray, w: np.ndarray) -> None:
        """Add per-pixel sums w (k, C + 1) from :meth:`pixel_sums_matrix` to the pixels (k,) int64
        (row-major indices y * width + x, each at most once)."""
        C = self.n_channels
        self._sum[pixels] += w[:, :C]
        self._wsum[pixels] += w[:, C]

    def combined_sums(self) -> tuple[np.ndarray, np.ndarray]:
        """(Combined RGB sums (H * W, 3) float32, sample counts (H * W,) float32): adaptive sampling's I, N."""
        c0 = self._first_channel("Combined")
        return self._sum[:, c0:c0 + 3], self._wsum

    def _first_channel(self, name: str) -> int:
        """First image channel of pass ``name`` in the film's pass order."""
        c0 = 0
        for n, c, _ in self.passes:
            if n == name:
                return c0
            c0 += c
        raise KeyError(name)

    def resolve(self) -> dict[str, np.ndarray]:
        """The passes as name -> (H, W, C) float32: sums over sample counts.

        A pixel that no sample reached (a film no tile was added to) is 0, with
        Depth = :data:`DEPTH_BACKGROUND`.
        """
        w = self._wsum[:, None]
        img = np.where(w > 0, self._sum / np.where(w > 0, w, 1.0), 0.0)
        out, c0 = {}, 0
        for name, c, _ in self.passes:
            a = img[:, c0:c0 + c].reshape(self.height, self.width, c)
            if name == "Depth":
                a = np.where(w.reshape(self.height, self.width, 1) > 0, a, DEPTH_BACKGROUND)
            out[name] = a.astype(np.float32)
            c0 += c
        return out
