"""Blender's procedural textures as scalar numba functions (Cycles 5.0 SVM formulas).

Every public function takes floats / ints and returns a tuple of floats; nothing allocates, so a
node program can call them once per shading point.  The formulas follow Cycles' SVM kernels
(``intern/cycles/kernel/svm/{noise,noisetex,fractal_noise,voronoi,wave,brick,magic,white_noise}.h``
and ``util/hash.h`` of Blender 5.0); the code here is written from those formulas.

Textures (coordinates are the node's Vector input, before the node's Scale):

* :func:`noise_texture` -- Perlin noise (1D-4D), fBM / multifractal / hybrid multifractal / ridged
  multifractal / hetero terrain, distortion, colour from two offset evaluations;
* :func:`voronoi_texture` -- F1, F2, smooth F1, distance to edge, n-sphere radius (1D-4D); four
  metrics; fractal detail / roughness / lacunarity and normalize;
* :func:`wave_texture` -- bands / rings, directions, sine / saw / triangle profiles, distortion;
* :func:`brick_texture` (+ :func:`brick_color`), :func:`magic_texture`, :func:`white_noise_texture`.

Enum dicts (``NOISE_TYPES``, ``VORONOI_FEATURES`` ...) map Blender's RNA enum identifiers to the
integer codes these functions take; the codes are Cycles' own.

Precision
---------
Cycles computes in float32, these functions in float64.  Where a float32 rounding decides *which*
lattice cell or hash a point falls on, or is amplified by large offsets, the float32 value is
reproduced (:func:`f32`): the node's ``coordinate * scale``, the octave coordinates of the
fractals, ``p + seed offset`` of the noise colour / distortion, the bits hashed by White Noise and
the 1D Voronoi.  Elsewhere results differ from Cycles by float32 rounding (about 1e-6 relative).

Calling
-------
The public functions are thin wrappers that convert their arguments to float64 / int64 / bool
and call the implementations (``_noise_texture`` ...): numba compiles one specialisation per
argument-type tuple, and a jitted caller passing literal ints (``noise_texture(..., 3, ...)``),
int32 codes or float32 values then re-specialises only the wrapper (~0.5 s), not the
implementation (5-10 s cold).  Noise Texture's Offset and Gain inputs are the two trailing
arguments of :func:`noise_texture` (defaults 0 and 1, Blender's).

Integer hashes: Bob Jenkins' lookup3 ``final`` / ``mix`` on unsigned 32-bit words and the PCG
2D / 3D / 4D hashes on signed 32-bit words are computed on int64 values masked to 32 bits
(``& 0xFFFFFFFF``): +, -, * and XOR give the right low 32 bits whatever int64 overflow does; only
right shifts and comparisons need the masked (or sign-wrapped, :func:`_s32`) value.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .sampling import JIT, JIT_INLINE

__all__ = ["NOISE_TYPES", "VORONOI_FEATURES", "VORONOI_METRICS", "WAVE_TYPES", "WAVE_BANDS_DIRECTIONS",
           "WAVE_RINGS_DIRECTIONS", "WAVE_PROFILES", "DIMENSIONS",
           "f32", "hash_uint", "hash_uint2", "hash_uint3", "hash_uint4", "float_bits",
           "hash_float_to_float", "hash_float2_to_float", "hash_float3_to_float", "hash_float4_to_float",
           "hash_pcg2d", "hash_pcg3d", "hash_pcg4d", "perlin", "snoise",
           "noise_texture", "voronoi_texture", "wave_texture", "brick_texture", "brick_color",
           "magic_texture", "white_noise_texture"]

# Blender RNA identifiers -> codes (Cycles' NodeNoiseType, NodeVoronoi*, NodeWave* orders)
NOISE_TYPES = {"MULTIFRACTAL": 0, "FBM": 1, "HYBRID_MULTIFRACTAL": 2, "RIDGED_MULTIFRACTAL": 3,
               "HETERO_TERRAIN": 4}
VORONOI_METRICS = {"EUCLIDEAN": 0, "MANHATTAN": 1, "CHEBYCHEV": 2, "MINKOWSKI": 3}
VORONOI_FEATURES = {"F1": 0, "F2": 1, "SMOOTH_F1": 2, "DISTANCE_TO_EDGE": 3, "N_SPHERE_RADIUS": 4}
WAVE_TYPES = {"BANDS": 0, "RINGS": 1}
WAVE_BANDS_DIRECTIONS = {"X": 0, "Y": 1, "Z": 2, "DIAGONAL": 3}
WAVE_RINGS_DIRECTIONS = {"X": 0, "Y": 1, "Z": 2, "SPHERICAL": 3}
WAVE_PROFILES = {"SIN": 0, "SAW": 1, "TRI": 2}
DIMENSIONS = {"1D": 1, "2D": 2, "3D": 3, "4D": 4}     # noise_dimensions / voronoi_dimensions / ...

NOISE_MULTIFRACTAL, NOISE_FBM, NOISE_HYBRID, NOISE_RIDGED, NOISE_HETERO = 0, 1, 2, 3, 4
VOR_EUCLIDEAN, VOR_MANHATTAN, VOR_CHEBYCHEV, VOR_MINKOWSKI = 0, 1, 2, 3
VOR_F1, VOR_F2, VOR_SMOOTH_F1, VOR_EDGE, VOR_RADIUS = 0, 1, 2, 3, 4

_M32 = 0xFFFFFFFF
_SEED = (0xDEADBEEF + 13) & _M32          # lookup3's initial word, before the + (words << 2)
_INV_2_32 = 1.0 / 4294967296.0            # 1 / (float)0xFFFFFFFFu: that float is 2^32
_INV_2_31 = 1.0 / 2147483648.0            # 1 / (float)0x7FFFFFFFu: that float is 2^31
_FLT_MAX = 3.4028234663852886e38


def _c32(v: float) -> float:
    """A float32 constant of Cycles' source (e.g. ``0.982f``) as the float64 it is."""
    return float(np.float32(v))


_NOISE_SCALE1 = 0.25
_NOISE_SCALE2 = _c32(0.6616)
_NOISE_SCALE3 = _c32(0.9820)
_NOISE_SCALE4 = _c32(0.8344)
_PI_2_F = _c32(math.pi / 2.0)
_2PI_F = _c32(2.0 * math.pi)
_WAVE_EPS = _c32(0.000001)
_WAVE_SHRINK = _c32(0.999999)


# ----------------------------------------------------------------------------
# float32 helpers
# ----------------------------------------------------------------------------
@njit(**JIT)
def f32(x):
    """x rounded to the nearest float32 (returned as a float64)."""
    return np.float64(np.float32(x))


@njit(**JIT)
def float_bits(x):
    """The IEEE bits of float32(x) as an int in [0, 2^32) (Cycles' ``__float_as_uint``)."""
    return np.int64(np.float32(x).view(np.uint32))


@njit(**JIT)
def _u2f(n):
    """``uint_to_float_incl``: float32(n) / 2^32 for n in [0, 2^32)."""
    return np.float64(np.float32(n)) * _INV_2_32


# ----------------------------------------------------------------------------
# Jenkins lookup3 (final / mix) on 32-bit words held in int64
# ----------------------------------------------------------------------------
@njit(**JIT_INLINE)            # called with literal shifts: one compile per literal otherwise
def _rot(x, k):
    return ((x << k) | (x >> (32 - k))) & 0xFFFFFFFF


@njit(**JIT)
def _final(a, b, c):
    """lookup3's final(a, b, c); returns c (the only word the hashes use)."""
    c = ((c ^ b) - _rot(b, 14)) & 0xFFFFFFFF
    a = ((a ^ c) - _rot(c, 11)) & 0xFFFFFFFF
    b = ((b ^ a) - _rot(a, 25)) & 0xFFFFFFFF
    c = ((c ^ b) - _rot(b, 16)) & 0xFFFFFFFF
    a = ((a ^ c) - _rot(c, 4)) & 0xFFFFFFFF
    b = ((b ^ a) - _rot(a, 14)) & 0xFFFFFFFF
    c = ((c ^ b) - _rot(b, 24)) & 0xFFFFFFFF
    return c


@njit(**JIT)
def hash_uint(kx):
    """Cycles' ``hash_uint`` of one 32-bit word (any int: its low 32 bits are used)."""
    a = (_SEED + 4 + kx) & 0xFFFFFFFF
    b = np.int64(_SEED + 4)
    return _final(a, b, b)


@njit(**JIT)
def hash_uint2(kx, ky):
    """Cycles' ``hash_uint2``."""
    s = np.int64(_SEED + 8)
    return _final((s + kx) & 0xFFFFFFFF, (s + ky) & 0xFFFFFFFF, s)


@njit(**JIT)
def hash_uint3(kx, ky, kz):
    """Cycles' ``hash_uint3``."""
    s = np.int64(_SEED + 12)
    return _final((s + kx) & 0xFFFFFFFF, (s + ky) & 0xFFFFFFFF, (s + kz) & 0xFFFFFFFF)


@njit(**JIT)
def hash_uint4(kx, ky, kz, kw):
    """Cycles' ``hash_uint4``: lookup3's mix of the first three words, then final with the fourth."""
    s = np.int64(_SEED + 16)
    a = (s + kx) & 0xFFFFFFFF
    b = (s + ky) & 0xFFFFFFFF
    c = (s + kz) & 0xFFFFFFFF
    a = ((a - c) ^ _rot(c, 4)) & 0xFFFFFFFF
    c = (c + b) & 0xFFFFFFFF
    b = ((b - a) ^ _rot(a, 6)) & 0xFFFFFFFF
    a = (a + c) & 0xFFFFFFFF
    c = ((c - b) ^ _rot(b, 8)) & 0xFFFFFFFF
    b = (b + a) & 0xFFFFFFFF
    a = ((a - c) ^ _rot(c, 16)) & 0xFFFFFFFF
    c = (c + b) & 0xFFFFFFFF
    b = ((b - a) ^ _rot(a, 19)) & 0xFFFFFFFF
    a = (a + c) & 0xFFFFFFFF
    c = ((c - b) ^ _rot(b, 4)) & 0xFFFFFFFF
    b = (b + a) & 0xFFFFFFFF
    a = (a + kw) & 0xFFFFFFFF
    return _final(a, b, c)


@njit(**JIT)
def hash_float_to_float(k):
    """Hash of float32(k)'s bits -> [0, 1]."""
    return _u2f(hash_uint(float_bits(k)))


@njit(**JIT)
def hash_float2_to_float(kx, ky):
    return _u2f(hash_uint2(float_bits(kx), float_bits(ky)))


@njit(**JIT)
def hash_float3_to_float(kx, ky, kz):
    return _u2f(hash_uint3(float_bits(kx), float_bits(ky), float_bits(kz)))


@njit(**JIT)
def hash_float4_to_float(kx, ky, kz, kw):
    return _u2f(hash_uint4(float_bits(kx), float_bits(ky), float_bits(kz), float_bits(kw)))


# ----------------------------------------------------------------------------
# PCG hashes on signed 32-bit ints (Voronoi's cell hashes)
# ----------------------------------------------------------------------------
@njit(**JIT)
def _s32(v):
    """Wrap an int64 to the signed 32-bit value with the same low 32 bits."""
    v = v & 0xFFFFFFFF
    return v - 0x100000000 if v >= 0x80000000 else v


@njit(**JIT)
def hash_pcg2d(x, y):
    """Cycles' ``hash_pcg2d_i``: two ints -> two ints in [0, 2^31)."""
    x = _s32(x * 1664525 + 1013904223)
    y = _s32(y * 1664525 + 1013904223)
    x = _s32(x + y * 1664525)
    y = _s32(y + x * 1664525)
    x = x ^ (x >> 16)
    y = y ^ (y >> 16)
    x = _s32(x + y * 1664525)
    y = _s32(y + x * 1664525)
    return x & 0x7FFFFFFF, y & 0x7FFFFFFF


@njit(**JIT_INLINE)            # called with a literal 0 too
def hash_pcg3d(x, y, z):
    """Cycles' ``hash_pcg3d_i``."""
    x = _s32(x * 1664525 + 1013904223)
    y = _s32(y * 1664525 + 1013904223)
    z = _s32(z * 1664525 + 1013904223)
    x = _s32(x + y * z)
    y = _s32(y + z * x)
    z = _s32(z + x * y)
    x = x ^ (x >> 16)
    y = y ^ (y >> 16)
    z = z ^ (z >> 16)
    x = _s32(x + y * z)
    y = _s32(y + z * x)
    z = _s32(z + x * y)
    return x & 0x7FFFFFFF, y & 0x7FFFFFFF, z & 0x7FFFFFFF


@njit(**JIT)
def hash_pcg4d(x, y, z, w):
    """Cycles' ``hash_pcg4d_i``."""
    x = _s32(x * 1664525 + 1013904223)
    y = _s32(y * 1664525 + 1013904223)
    z = _s32(z * 1664525 + 1013904223)
    w = _s32(w * 1664525 + 1013904223)
    x = _s32(x + y * w)
    y = _s32(y + z * x)
    z = _s32(z + x * y)
    w = _s32(w + y * z)
    x = x ^ (x >> 16)
    y = y ^ (y >> 16)
    z = z ^ (z >> 16)
    w = w ^ (w >> 16)
    x = _s32(x + y * w)
    y = _s32(y + z * x)
    z = _s32(z + x * y)
    w = _s32(w + y * z)
    return x & 0x7FFFFFFF, y & 0x7FFFFFFF, z & 0x7FFFFFFF, w & 0x7FFFFFFF


@njit(**JIT)
def _i2f(h):
    """PCG output (an int in [0, 2^31)) -> [0, 1]: float32(h) / 2^31."""
    return np.float64(np.float32(h)) * _INV_2_31


# ----------------------------------------------------------------------------
# Perlin noise
# ----------------------------------------------------------------------------
@njit(**JIT)
def _fade(t):
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@njit(**JIT)
def _neg(v, cond):
    return -v if cond != 0 else v


@njit(**JIT)
def _lerp(a, b, t):
    return a + t * (b - a)


@njit(**JIT)
def _corner_grad(X, Y, Z, W, i, j, k, m, xa, xb, xc, xd, dims):
    """Gradient term of lattice corner (X + i, Y + j, Z + k, W + m) at the offset (xa, xb, xc, xd)."""
    if dims == 1:
        h = hash_uint(X + i) & 15
        return _neg(1.0 + (h & 7), h & 8) * xa
    if dims == 2:
        h = hash_uint2(X + i, Y + j) & 7
        u = xa if h < 4 else xb
        v = 2.0 * (xb if h < 4 else xa)
        return _neg(u, h & 1) + _neg(v, h & 2)
    if dims == 3:
        h = hash_uint3(X + i, Y + j, Z + k) & 15
        u = xa if h < 8 else xb
        v = xb if h < 4 else (xa if (h == 12 or h == 14) else xc)
        return _neg(u, h & 1) + _neg(v, h & 2)
    h = hash_uint4(X + i, Y + j, Z + k, W + m) & 31
    u = xa if h < 24 else xb
    v = xb if h < 16 else xc
    s = xc if h < 8 else xd
    return _neg(u, h & 1) + _neg(v, h & 2) + _neg(s, h & 4)


@njit(**JIT)
def perlin(a, b, c, d, dims):
    """Blender's (unscaled) Perlin noise of the first ``dims`` coordinates (Cycles' ``perlin_{1..4}d``):
    quintic fade, gradients chosen by the lookup3 hash of the lattice corner, multilinear blend of
    the 2^dims corners (the blend is summed as weights x gradients: same value as Cycles' nested
    mixes up to float rounding)."""
    fa, fb, fc, fd = np.floor(a), np.floor(b), np.floor(c), np.floor(d)
    X, Y, Z, W = np.int64(fa), np.int64(fb), np.int64(fc), np.int64(fd)
    la, lb, lc, ld = a - fa, b - fb, c - fc, d - fd
    ua, ub, uc, ud = _fade(la), _fade(lb), _fade(lc), _fade(ld)
    r = 0.0
    for corner in range(1 << dims):
        i, j, k, m = corner & 1, (corner >> 1) & 1, (corner >> 2) & 1, corner >> 3
        wgt = ua if i else 1.0 - ua
        if dims >= 2:
            wgt *= ub if j else 1.0 - ub
        if dims >= 3:
            wgt *= uc if k else 1.0 - uc
        if dims >= 4:
            wgt *= ud if m else 1.0 - ud
        r += wgt * _corner_grad(X, Y, Z, W, i, j, k, m, la - i, lb - j, lc - k, ld - m, dims)
    return r


@njit(**JIT)
def _wrap(p):
    """float32(p), repeated every 100000 (plus 0.5 beyond 1e6), as Cycles' snoise does."""
    p = f32(p)
    if abs(p) < 100000.0:                        # fmod(p, 1e5) == p: skip the libm call
        return p
    corr = 0.5 if abs(p) >= 1000000.0 else 0.0
    return f32(np.fmod(p, 100000.0) + corr)


@njit(**JIT)
def snoise(a, b, c, d, dims):
    """Signed noise in about [-1, 1] of the first ``dims`` coordinates (Cycles' ``snoise_{1..4}d``)."""
    if dims == 1:
        s = _NOISE_SCALE1
    elif dims == 2:
        s = _NOISE_SCALE2
    elif dims == 3:
        s = _NOISE_SCALE3
    else:
        s = _NOISE_SCALE4
    return s * perlin(_wrap(a), _wrap(b), _wrap(c), _wrap(d), dims)


# ----------------------------------------------------------------------------
# Fractals (coordinates (a, b, c, d), the first dims used; float32 values)
# ----------------------------------------------------------------------------
@njit(**JIT)
def _fractal(a, b, c, d, dims, detail, roughness, lacunarity, offset, gain, noise_type, normalize):
    """Cycles' noise_fbm / noise_multi_fractal / noise_hetero_terrain / noise_hybrid_multi_fractal /
    noise_ridged_multi_fractal in one octave loop (one noise call site: less code to compile).

    Octaves 0 .. int(detail), then (but for ridged) a partial octave weighted by detail's fraction.
    fBM evaluates octave k at float32(p * s_k), s_k the float32 product of lacunarities; the others
    scale p itself by the lacunarity after each octave (float32 each time), as Cycles does.
    """
    n = int(detail)
    rmd = detail - np.floor(detail)
    octaves = n + 1
    if rmd != 0.0 and noise_type != NOISE_RIDGED:
        octaves += 1
    fbm = noise_type != NOISE_MULTIFRACTAL and noise_type != NOISE_HYBRID and noise_type != NOISE_RIDGED \
        and noise_type != NOISE_HETERO
    fscale = 1.0
    amp = 1.0
    maxamp = 0.0
    total = 0.0
    value = 1.0 if noise_type == NOISE_MULTIFRACTAL else 0.0
    pwr = roughness if (noise_type == NOISE_HETERO or noise_type == NOISE_RIDGED) else 1.0
    weight = 1.0
    signal = 0.0
    for i in range(octaves):
        partial = i > n
        if noise_type == NOISE_HYBRID:
            if not weight > 0.001:
                break
            weight = min(weight, 1.0)
        if fbm:
            t = snoise(fscale * a, fscale * b, fscale * c, fscale * d, dims)
        else:
            t = snoise(a, b, c, d, dims)
        if fbm:
            if partial:
                total2 = total + t * amp
                if normalize:
                    return _lerp(0.5 * total / maxamp + 0.5, 0.5 * total2 / (maxamp + amp) + 0.5, rmd)
                return _lerp(total, total2, rmd)
            total += t * amp
            maxamp += amp
            amp *= roughness
            fscale = f32(fscale * lacunarity)
            continue
        if noise_type == NOISE_MULTIFRACTAL:
            if partial:
                value *= rmd * pwr * t + 1.0
            else:
                value *= pwr * t + 1.0
                pwr *= roughness
        elif noise_type == NOISE_HETERO:
            if i == 0:
                value = offset + t
            else:
                increment = (t + offset) * pwr * value
                if partial:
                    value += rmd * increment
                else:
                    value += increment
                    pwr *= roughness
        elif noise_type == NOISE_HYBRID:
            sig = (t + offset) * pwr
            if partial:
                value += rmd * weight * sig
            else:
                pwr *= roughness
                value += weight * sig
                weight *= gain * sig
        else:                                            # ridged
            if i == 0:
                signal = offset - abs(t)
                signal *= signal
                value = signal
            else:
                w = min(max(signal * gain, 0.0), 1.0)
                signal = offset - abs(t)
                signal = signal * signal * w
                value += signal * pwr
                pwr *= roughness
        a, b, c, d = f32(a * lacunarity), f32(b * lacunarity), f32(c * lacunarity), f32(d * lacunarity)
    if fbm:
        return 0.5 * total / maxamp + 0.5 if normalize else total
    return value


@njit(**JIT)
def _seed_offset(dims, seed, comp):
    """Cycles' ``random_float{,2,3,4}_offset(seed)`` component ``comp``: in [100, 200], float32."""
    if dims == 1:
        h = hash_float_to_float(seed)
    else:
        h = hash_float2_to_float(seed, comp)
    return f32(100.0 + f32(h * 100.0))


@njit(**JIT)
def _offset_point(a, b, c, d, dims, seed):
    """float32(p + random offset(seed)) on the first dims coordinates."""
    a = f32(a + _seed_offset(dims, seed, 0.0))
    if dims >= 2:
        b = f32(b + _seed_offset(dims, seed, 1.0))
    if dims >= 3:
        c = f32(c + _seed_offset(dims, seed, 2.0))
    if dims >= 4:
        d = f32(d + _seed_offset(dims, seed, 3.0))
    return a, b, c, d


@njit(**JIT)
def _noise_texture(x, y, z, w, dims, scale, detail, roughness, lacunarity, distortion, normalize, noise_type,
                   offset, gain, color):
    """See :func:`noise_texture`."""
    detail = min(max(detail, 0.0), 15.0)
    roughness = max(roughness, 0.0)
    if dims == 1:
        a, b, c, d = f32(w * scale), 0.0, 0.0, 0.0
    else:
        a, b = f32(x * scale), f32(y * scale)
        c = f32(z * scale) if dims >= 3 else 0.0
        d = f32(w * scale) if dims >= 4 else 0.0
    if distortion != 0.0:
        da, db, dc, dd = 0.0, 0.0, 0.0, 0.0
        for j in range(dims):
            qa, qb, qc, qd = _offset_point(a, b, c, d, dims, float(j))
            n = f32(snoise(qa, qb, qc, qd, dims) * distortion)
            if j == 0:
                da = n
            elif j == 1:
                db = n
            elif j == 2:
                dc = n
            else:
                dd = n
        a, b = f32(a + da), f32(b + db)
        c, d = f32(c + dc), f32(d + dd)
    seed = 1.0 if dims == 1 else float(dims)    # colour seeds: 1, 2 (1D); 2, 3 (2D); 3, 4 (3D); 4, 5 (4D)
    v0, v1, v2 = 0.0, 0.0, 0.0
    for ch in range(3 if color else 1):
        if ch == 0:
            qa, qb, qc, qd = a, b, c, d
        else:
            qa, qb, qc, qd = _offset_point(a, b, c, d, dims, seed + (ch - 1))
        v = _fractal(qa, qb, qc, qd, dims, detail, roughness, lacunarity, offset, gain, noise_type, normalize)
        if ch == 0:
            v0 = v
        elif ch == 1:
            v1 = v
        else:
            v2 = v
    if not color:
        return v0, 0.0, 0.0, 0.0
    return v0, v0, v1, v2


# ----------------------------------------------------------------------------
# Voronoi (coordinates (a, b, c, d), the first dims used)
# ----------------------------------------------------------------------------
@njit(**JIT)
def _vor_point(ia, ib, ic, id_, dims):
    """Feature-point offset of the integer cell (ia, ib, ic, id_): components in [0, 1].  In 3D and 4D
    its first three components are also the cell's colour (Cycles hashes the cell once for both)."""
    if dims == 1:
        return hash_float_to_float(float(ia)), 0.0, 0.0, 0.0
    if dims == 2:
        hx, hy = hash_pcg2d(ia, ib)
        return _i2f(hx), _i2f(hy), 0.0, 0.0
    if dims == 3:
        hx, hy, hz = hash_pcg3d(ia, ib, ic)
        return _i2f(hx), _i2f(hy), _i2f(hz), 0.0
    hx, hy, hz, hw = hash_pcg4d(ia, ib, ic, id_)
    return _i2f(hx), _i2f(hy), _i2f(hz), _i2f(hw)


@njit(**JIT)
def _vor_color_12(ia, ib, dims):
    """Cell colour in 1D (hash_float_to_float3 of the cell) and 2D (PCG 3D of (x, y, 0))."""
    if dims == 1:
        k = float(ia)
        return hash_float_to_float(k), hash_float2_to_float(k, 1.0), hash_float2_to_float(k, 2.0)
    hx, hy, hz = hash_pcg3d(ia, ib, 0)
    return _i2f(hx), _i2f(hy), _i2f(hz)


@njit(**JIT_INLINE)            # called with a literal bound too
def _vor_dist(da, db, dc, dd, dims, metric, exponent, bound):
    """Distance of the difference vector under ``metric`` (1D: |da|); bound: the cheaper monotone
    stand-in Cycles compares in F1 (squared Euclidean, Minkowski without the root)."""
    if dims == 1:
        return abs(da)
    if metric == VOR_EUCLIDEAN:
        s = da * da + db * db + dc * dc + dd * dd
        return s if bound else math.sqrt(s)
    if metric == VOR_MANHATTAN:
        return abs(da) + abs(db) + abs(dc) + abs(dd)
    if metric == VOR_CHEBYCHEV:
        return max(max(abs(da), abs(db)), max(abs(dc), abs(dd)))
    if metric == VOR_MINKOWSKI:
        s = abs(da) ** exponent + abs(db) ** exponent
        if dims >= 3:
            s += abs(dc) ** exponent
        if dims >= 4:
            s += abs(dd) ** exponent
        return s if bound else s ** (1.0 / exponent)
    return 0.0


@njit(**JIT)
def _vor_octave(a, b, c, d, dims, feature, metric, exponent, randomness, smoothness):
    """One octave of F1 / F2 / smooth F1 -> (distance, r, g, b, pa, pb, pc, pd) (position absolute)."""
    fa, fb, fc, fd = np.floor(a), np.floor(b), np.floor(c), np.floor(d)
    la, lb, lc, ld = a - fa, b - fb, c - fc, d - fd
    ia, ib, ic, id_ = np.int64(fa), np.int64(fb), np.int64(fc), np.int64(fd)
    smooth = feature == VOR_SMOOTH_F1
    bound = feature == VOR_F1
    rad = 2 if smooth else 1
    rj = rad if dims >= 2 else 0
    rk = rad if dims >= 3 else 0
    ru = rad if dims >= 4 else 0
    # nearest (1) and second nearest (2): distance, cell offset, point, point hash
    d1 = _FLT_MAX
    d2 = _FLT_MAX
    o1 = (0, 0, 0, 0)
    o2 = (0, 0, 0, 0)
    p1 = (0.0, 0.0, 0.0, 0.0)
    p2 = (0.0, 0.0, 0.0, 0.0)
    h1 = (0.0, 0.0, 0.0, 0.0)
    h2 = (0.0, 0.0, 0.0, 0.0)
    # smooth F1 accumulators
    sd = 0.0
    sr, sg, sb = 0.0, 0.0, 0.0
    sa, sb_, sc, sdd = 0.0, 0.0, 0.0, 0.0
    h = -1.0
    for u in range(-ru, ru + 1):
        for k in range(-rk, rk + 1):
            for j in range(-rj, rj + 1):
                for i in range(-rad, rad + 1):
                    ha, hb, hc, hd = _vor_point(ia + i, ib + j, ic + k, id_ + u, dims)
                    pa = i + ha * randomness
                    pb = j + hb * randomness
                    pc = k + hc * randomness
                    pd = u + hd * randomness
                    dist = _vor_dist(pa - la, pb - lb, pc - lc, pd - ld, dims, metric, exponent, bound)
                    if smooth:
                        if h == -1.0:
                            h = 1.0
                        else:
                            t = 0.5 + 0.5 * (sd - dist) / smoothness
                            h = 0.0 if t < 0.0 else (1.0 if t >= 1.0 else (3.0 - 2.0 * t) * (t * t))
                        corr = smoothness * h * (1.0 - h)
                        sd = _lerp(sd, dist, h) - corr
                        corr /= 1.0 + 3.0 * smoothness
                        if dims >= 3:
                            cr, cg, cb = ha, hb, hc
                        else:
                            cr, cg, cb = _vor_color_12(ia + i, ib + j, dims)
                        sr = _lerp(sr, cr, h) - corr
                        sg = _lerp(sg, cg, h) - corr
                        sb = _lerp(sb, cb, h) - corr
                        sa = _lerp(sa, pa, h) - corr
                        sb_ = _lerp(sb_, pb, h) - corr
                        sc = _lerp(sc, pc, h) - corr
                        sdd = _lerp(sdd, pd, h) - corr
                    elif dist < d1:
                        d2, o2, p2, h2 = d1, o1, p1, h1
                        d1, o1, p1, h1 = dist, (i, j, k, u), (pa, pb, pc, pd), (ha, hb, hc, hd)
                    elif dist < d2:
                        d2, o2, p2, h2 = dist, (i, j, k, u), (pa, pb, pc, pd), (ha, hb, hc, hd)
    if smooth:
        return (sd, sr, sg, sb, fa + sa, fb + (sb_ if dims >= 2 else 0.0), fc + (sc if dims >= 3 else 0.0),
                fd + (sdd if dims >= 4 else 0.0))
    if feature == VOR_F1:
        dist, o, p, hh = d1, o1, p1, h1
        if dims >= 2 and (metric == VOR_EUCLIDEAN or metric == VOR_MINKOWSKI):   # bound -> distance
            dist = math.sqrt(dist) if metric == VOR_EUCLIDEAN else dist ** (1.0 / exponent)
    else:
        dist, o, p, hh = d2, o2, p2, h2
    if dims >= 3:
        r, g, bl = hh[0], hh[1], hh[2]
    else:
        r, g, bl = _vor_color_12(ia + o[0], ib + o[1], dims)
    return dist, r, g, bl, p[0] + fa, p[1] + fb, p[2] + fc, p[3] + fd


@njit(**JIT)
def _vor_two_pass(a, b, c, d, dims, randomness, edge):
    """Distance to the nearest cell edge (edge True; one octave) or the n-sphere radius (half the
    distance from the nearest feature point to its own nearest neighbour); Euclidean, as in Cycles."""
    fa, fb, fc, fd = np.floor(a), np.floor(b), np.floor(c), np.floor(d)
    la, lb, lc, ld = a - fa, b - fb, c - fc, d - fd
    if edge and dims == 1:
        mid = hash_float_to_float(fa) * randomness
        left = -1.0 + hash_float_to_float(fa - 1.0) * randomness
        right = 1.0 + hash_float_to_float(fa + 1.0) * randomness
        return min(abs((mid + left) / 2.0 - la), abs((mid + right) / 2.0 - la))
    ia, ib, ic, id_ = np.int64(fa), np.int64(fb), np.int64(fc), np.int64(fd)
    rj = 1 if dims >= 2 else 0
    rk = 1 if dims >= 3 else 0
    ru = 1 if dims >= 4 else 0
    best = _FLT_MAX
    q = (0.0, 0.0, 0.0, 0.0)          # nearest point, relative to the local position (edge) or the cell
    o = (0, 0, 0, 0)                  # centre of the search: the cell, then (radius) the nearest point's cell
    bo = o
    nearest = q
    for pass_ in range(2):
        if pass_ == 1:
            best = _FLT_MAX
            if not edge:
                o = bo
        for u in range(-ru, ru + 1):
            for k in range(-rk, rk + 1):
                for j in range(-rj, rj + 1):
                    for i in range(-1, 2):
                        if pass_ == 1 and not edge and i == 0 and j == 0 and k == 0 and u == 0:
                            continue
                        oi, oj, ok, ou = i + o[0], j + o[1], k + o[2], u + o[3]
                        ha, hb, hc, hd = _vor_point(ia + oi, ib + oj, ic + ok, id_ + ou, dims)
                        pa = oi + ha * randomness
                        pb = oj + hb * randomness
                        pc = ok + hc * randomness
                        pd = ou + hd * randomness
                        if edge:
                            pa, pb, pc, pd = pa - la, pb - lb, pc - lc, pd - ld
                        if pass_ == 0:
                            if edge:
                                dist = pa * pa + pb * pb + pc * pc + pd * pd
                            else:
                                dist = (pa - la) ** 2 + (pb - lb) ** 2 + (pc - lc) ** 2 + (pd - ld) ** 2
                            if dist < best:
                                best = dist
                                q = (pa, pb, pc, pd)
                                bo = (i, j, k, u)
                            continue
                        ea, eb, ec, ed = pa - q[0], pb - q[1], pc - q[2], pd - q[3]
                        e2 = ea * ea + eb * eb + ec * ec + ed * ed
                        if edge:
                            if e2 > 0.0001:
                                de = ((q[0] + pa) / 2.0 * ea + (q[1] + pb) / 2.0 * eb + (q[2] + pc) / 2.0 * ec
                                      + (q[3] + pd) / 2.0 * ed) / math.sqrt(e2)
                                best = min(best, de)
                        elif e2 < best:
                            best = e2
                            nearest = (pa, pb, pc, pd)
    if edge:
        return best
    return math.sqrt((nearest[0] - q[0]) ** 2 + (nearest[1] - q[1]) ** 2 + (nearest[2] - q[2]) ** 2
                     + (nearest[3] - q[3]) ** 2) / 2.0


@njit(**JIT)
def _vor_fractal(a, b, c, d, dims, scale, detail, roughness, lacunarity, smoothness, exponent, randomness,
                 feature, metric, normalize, max_distance):
    """Fractal F1 / F2 / smooth F1 -> (distance, r, g, b, pa, pb, pc, pd)."""
    amp = 1.0
    max_amp = 0.0
    sc = 1.0
    od, orr, og, ob = 0.0, 0.0, 0.0, 0.0
    pa, pb, pc, pd = 0.0, 0.0, 0.0, 0.0
    zero_input = detail == 0.0 or roughness == 0.0
    octave_feature = feature
    if feature == VOR_SMOOTH_F1 and smoothness == 0.0:
        octave_feature = VOR_F1
    for i in range(int(np.ceil(detail)) + 1):
        (dist, r, g, bl, qa, qb, qc, qd) = _vor_octave(f32(a * sc), f32(b * sc), f32(c * sc), f32(d * sc), dims,
                                                       octave_feature, metric, exponent, randomness, smoothness)
        if zero_input:
            max_amp = 1.0
            od, orr, og, ob, pa, pb, pc, pd = dist, r, g, bl, qa, qb, qc, qd
            break
        if i <= detail:
            max_amp += amp
            od += dist * amp
            orr += r * amp
            og += g * amp
            ob += bl * amp
            pa = _lerp(pa, qa / sc, amp)
            pb = _lerp(pb, qb / sc, amp)
            pc = _lerp(pc, qc / sc, amp)
            pd = _lerp(pd, qd / sc, amp)
            sc = f32(sc * lacunarity)
            amp *= roughness
        else:
            rem = detail - np.floor(detail)
            if rem != 0.0:
                max_amp = _lerp(max_amp, max_amp + amp, rem)
                od = _lerp(od, od + dist * amp, rem)
                orr = _lerp(orr, orr + r * amp, rem)
                og = _lerp(og, og + g * amp, rem)
                ob = _lerp(ob, ob + bl * amp, rem)
                pa = _lerp(pa, _lerp(pa, qa / sc, amp), rem)
                pb = _lerp(pb, _lerp(pb, qb / sc, amp), rem)
                pc = _lerp(pc, _lerp(pc, qc / sc, amp), rem)
                pd = _lerp(pd, _lerp(pd, qd / sc, amp), rem)
    if normalize:
        od /= max_amp * max_distance
        orr /= max_amp
        og /= max_amp
        ob /= max_amp
    if scale != 0.0:
        pa, pb, pc, pd = pa / scale, pb / scale, pc / scale, pd / scale
    else:
        pa, pb, pc, pd = 0.0, 0.0, 0.0, 0.0
    return od, orr, og, ob, pa, pb, pc, pd


@njit(**JIT)
def _vor_fractal_edge(a, b, c, d, dims, detail, roughness, lacunarity, randomness, normalize, max_distance, edge):
    """Fractal distance to edge (edge True); edge False: the n-sphere radius (no octaves, as in Cycles).
    One call site of the two-pass search for both."""
    amp = 1.0
    max_amp = max_distance
    sc = 1.0
    dist = 8.0
    zero_input = detail == 0.0 or roughness == 0.0
    for i in range(int(np.ceil(detail)) + 1):
        od = _vor_two_pass(f32(a * sc), f32(b * sc), f32(c * sc), f32(d * sc), dims, randomness, edge)
        if zero_input or not edge:
            dist = od
            break
        if i <= detail:
            max_amp = _lerp(max_amp, max_distance / sc, amp)
            dist = _lerp(dist, min(dist, od / sc), amp)
            sc = f32(sc * lacunarity)
            amp *= roughness
        else:
            rem = detail - np.floor(detail)
            if rem != 0.0:
                lerp_amp = _lerp(max_amp, max_distance / sc, amp)
                max_amp = _lerp(max_amp, lerp_amp, rem)
                lerp_dist = _lerp(dist, min(dist, od / sc), amp)
                dist = _lerp(dist, min(dist, lerp_dist), rem)
    if normalize and edge:
        dist /= max_amp
    return dist


@njit(**JIT)
def _voronoi_texture(x, y, z, w, dims, scale, detail, roughness, lacunarity, smoothness, exponent, randomness,
                     feature, metric, normalize):
    """See :func:`voronoi_texture`."""
    detail = min(max(detail, 0.0), 15.0)
    roughness = min(max(roughness, 0.0), 1.0)
    randomness = min(max(randomness, 0.0), 1.0)
    smoothness = min(max(smoothness / 2.0, 0.0), 0.5)
    if dims == 1:
        a, b, c, d = f32(w * scale), 0.0, 0.0, 0.0
    else:
        a, b = f32(x * scale), f32(y * scale)
        c = f32(z * scale) if dims >= 3 else 0.0
        d = f32(w * scale) if dims >= 4 else 0.0
    m = 0.5 + 0.5 * randomness
    if feature == VOR_EDGE or feature == VOR_RADIUS:
        edge = feature == VOR_EDGE
        dist = _vor_fractal_edge(a, b, c, d, dims, detail, roughness, lacunarity, randomness, normalize, m, edge)
        if edge:
            return dist, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, dist
    max_distance = m if dims == 1 else _vor_dist(m, m, m if dims >= 3 else 0.0, m if dims >= 4 else 0.0, dims,
                                                 metric, exponent, False)
    if feature == VOR_F2:
        max_distance *= 2.0
    dist, r, g, bl, pa, pb, pc, pd = _vor_fractal(a, b, c, d, dims, scale, detail, roughness, lacunarity,
                                                  smoothness, exponent, randomness, feature, metric, normalize,
                                                  max_distance)
    if dims == 1:
        return dist, r, g, bl, 0.0, 0.0, 0.0, pa, 0.0
    return dist, r, g, bl, pa, pb, (pc if dims >= 3 else 0.0), (pd if dims >= 4 else 0.0), 0.0


# ----------------------------------------------------------------------------
# Wave, brick, magic, white noise
# ----------------------------------------------------------------------------
@njit(**JIT)
def _wave_texture(x, y, z, wave_type, bands_direction, rings_direction, profile, scale, distortion, detail,
                  detail_scale, detail_roughness, phase):
    """See :func:`wave_texture`."""
    px = f32((f32(f32(x * scale) + _WAVE_EPS)) * _WAVE_SHRINK)
    py = f32((f32(f32(y * scale) + _WAVE_EPS)) * _WAVE_SHRINK)
    pz = f32((f32(f32(z * scale) + _WAVE_EPS)) * _WAVE_SHRINK)
    if wave_type == 0:
        if bands_direction == 0:
            n = px * 20.0
        elif bands_direction == 1:
            n = py * 20.0
        elif bands_direction == 2:
            n = pz * 20.0
        else:
            n = (px + py + pz) * 10.0
    else:
        rx = 0.0 if rings_direction == 0 else px
        ry = 0.0 if rings_direction == 1 else py
        rz = 0.0 if rings_direction == 2 else pz
        n = math.sqrt(rx * rx + ry * ry + rz * rz) * 20.0
    n += phase
    if distortion != 0.0:
        dt = min(max(detail, 0.0), 15.0)
        fbm = _fractal(f32(px * detail_scale), f32(py * detail_scale), f32(pz * detail_scale), 0.0, np.int64(3), dt,
                       detail_roughness, 2.0, 0.0, 1.0, np.int64(NOISE_FBM), np.bool_(True))
        n += distortion * (fbm * 2.0 - 1.0)
    if profile == 0:
        fac = 0.5 + 0.5 * math.sin(n - _PI_2_F)
    elif profile == 1:
        n /= _2PI_F
        fac = n - np.floor(n)
    else:
        n /= _2PI_F
        fac = abs(n - np.floor(n + 0.5)) * 2.0
    return fac, fac, fac, fac


@njit(**JIT)
def _brick_noise(n):
    n = (n + 1013) & 0x7FFFFFFF
    n = (n >> 13) ^ n
    t = (n * n) & 0xFFFFFFFF
    t = (t * 60493 + 19990303) & 0xFFFFFFFF
    nn = (n * t + 1376312589) & 0x7FFFFFFF
    return 0.5 * (np.float64(np.float32(nn)) / 1073741824.0)


@njit(**JIT)
def _brick_texture(x, y, z, scale, mortar_size, mortar_smooth, bias, brick_width, row_height, offset_amount,
                   offset_frequency, squash_amount, squash_frequency):
    """See :func:`brick_texture`."""
    px = f32(x * scale)
    py = f32(y * scale)
    rownum = np.int64(np.floor(f32(py / row_height)))
    offset = 0.0
    bw = brick_width
    if offset_frequency != 0 and squash_frequency != 0:
        if rownum % squash_frequency == 0:
            bw = f32(bw * squash_amount)
        offset = 0.0 if rownum % offset_frequency != 0 else f32(bw * offset_amount)
    sx = f32(px + offset)
    bricknum = np.int64(np.floor(f32(sx / bw)))
    bx = sx - bw * bricknum
    by = py - row_height * rownum
    tint = min(max(_brick_noise((rownum << 16) + (bricknum & 0xFFFF)) + bias, 0.0), 1.0)
    min_dist = min(min(bx, by), min(bw - bx, row_height - by))
    if min_dist >= mortar_size:
        mortar = 0.0
    elif mortar_smooth == 0.0:
        mortar = 1.0
    else:
        f = (1.0 - min_dist / mortar_size) / mortar_smooth
        mortar = 0.0 if f <= 0.0 else (1.0 if f >= 1.0 else 3.0 * f * f - 2.0 * f * f * f)
    return mortar, tint


@njit(**JIT)
def brick_color(fac, tint, c1r, c1g, c1b, c2r, c2g, c2b, mr, mg, mb):
    """Brick Color output from :func:`brick_texture`'s (fac, tint) and the Color1 / Color2 / Mortar inputs."""
    if fac != 1.0:
        c1r = (1.0 - tint) * c1r + tint * c2r
        c1g = (1.0 - tint) * c1g + tint * c2g
        c1b = (1.0 - tint) * c1b + tint * c2b
    return (c1r * (1.0 - fac) + mr * fac, c1g * (1.0 - fac) + mg * fac, c1b * (1.0 - fac) + mb * fac)


@njit(**JIT)
def _magic_texture(x, y, z, depth, scale, distortion):
    """See :func:`magic_texture`."""
    px = np.fmod(f32(x), _2PI_F)
    py = np.fmod(f32(y), _2PI_F)
    pz = np.fmod(f32(z), _2PI_F)
    a = math.sin(f32(f32(f32(f32(px + py) + pz) * 5.0) * scale))
    b = math.cos(f32(f32(f32(f32(py - px) - pz) * 5.0) * scale))
    c = -math.cos(f32(f32(f32(f32(-px - py) + pz) * 5.0) * scale))
    n = depth
    if n > 0:
        a *= distortion
        b *= distortion
        c *= distortion
        b = -math.cos(a - b + c) * distortion
        if n > 1:
            a = math.cos(a - b - c) * distortion
            if n > 2:
                c = math.sin(-a - b - c) * distortion
                if n > 3:
                    a = -math.cos(-a + b - c) * distortion
                    if n > 4:
                        b = -math.sin(-a + b + c) * distortion
                        if n > 5:
                            b = -math.cos(-a + b + c) * distortion
                            if n > 6:
                                a = math.cos(a + b + c) * distortion
                                if n > 7:
                                    c = math.sin(a + b - c) * distortion
                                    if n > 8:
                                        a = -math.cos(-a - b + c) * distortion
                                        if n > 9:
                                            b = -math.sin(a - b + c) * distortion
    if distortion != 0.0:
        two_d = distortion * 2.0
        a /= two_d
        b /= two_d
        c /= two_d
    r, g, bl = 0.5 - a, 0.5 - b, 0.5 - c
    return (r + g + bl) * (1.0 / 3.0), r, g, bl


@njit(**JIT)
def _white_noise_texture(x, y, z, w, dims):
    """See :func:`white_noise_texture`."""
    if dims == 1:
        v = hash_float_to_float(w)
        return v, v, hash_float2_to_float(w, 1.0), hash_float2_to_float(w, 2.0)
    if dims == 2:
        v = hash_float2_to_float(x, y)
        return v, v, hash_float3_to_float(x, y, 1.0), hash_float3_to_float(x, y, 2.0)
    if dims == 3:
        v = hash_float3_to_float(x, y, z)
        return v, v, hash_float4_to_float(x, y, z, 1.0), hash_float4_to_float(x, y, z, 2.0)
    v = hash_float4_to_float(x, y, z, w)
    return v, v, hash_float4_to_float(z, x, w, y), hash_float4_to_float(w, z, y, x)


# ----------------------------------------------------------------------------
# Public entry points: thin wrappers that fix the argument types of the implementations
# (float64 / int64 / bool), so that a caller passing literal or narrower ints, bools or float32
# values re-specialises only the wrapper, never the large functions below it.
# ----------------------------------------------------------------------------
@njit(**JIT)
def noise_texture(x, y, z, w, dims, scale, detail, roughness, lacunarity, distortion, normalize, noise_type,
                  offset=0.0, gain=1.0, color=True):
    """Noise Texture node -> (fac, r, g, b).

    (x, y, z) the Vector input, w the W input; dims 1 (uses w), 2 (x, y), 3 (x, y, z) or 4.
    noise_type a code of :data:`NOISE_TYPES`; normalize (FBM only) maps the sum to about [0, 1];
    offset and gain: the node's Offset and Gain inputs (hybrid / ridged / hetero types).
    Colour = (fac, the fractal at p + random offset A, at p + random offset B), so r == fac;
    distortion moves p by a noise per axis first (seeds 0 .. dims - 1).  color False (the node's
    Color output unused, as Cycles checks): only fac is computed, a third of the work; r, g, b = 0.
    """
    return _noise_texture(np.float64(x), np.float64(y), np.float64(z), np.float64(w), np.int64(dims),
                          np.float64(scale), np.float64(detail), np.float64(roughness), np.float64(lacunarity),
                          np.float64(distortion), normalize != 0, np.int64(noise_type), np.float64(offset),
                          np.float64(gain), color != 0)


@njit(**JIT)
def voronoi_texture(x, y, z, w, dims, scale, detail, roughness, lacunarity, smoothness, exponent, randomness,
                    feature, metric, normalize):
    """Voronoi Texture node -> (distance, r, g, b, px, py, pz, w_out, radius).

    dims 1 uses w, 2 (x, y), 3 (x, y, z), 4 (x, y, z, w); feature / metric codes of
    :data:`VORONOI_FEATURES` / :data:`VORONOI_METRICS`; exponent: the Minkowski exponent;
    smoothness: the node's Smoothness input (smooth F1).  Distance to edge fills only distance,
    n-sphere radius only radius (the rest 0), as Cycles does.  Position (px, py, pz) and W: the
    feature point in the node's input space (divided by scale).
    """
    return _voronoi_texture(np.float64(x), np.float64(y), np.float64(z), np.float64(w), np.int64(dims),
                            np.float64(scale), np.float64(detail), np.float64(roughness), np.float64(lacunarity),
                            np.float64(smoothness), np.float64(exponent), np.float64(randomness), np.int64(feature),
                            np.int64(metric), normalize != 0)


@njit(**JIT)
def wave_texture(x, y, z, wave_type, bands_direction, rings_direction, profile, scale, distortion, detail,
                 detail_scale, detail_roughness, phase):
    """Wave Texture node -> (fac, r, g, b) (colour = fac grey).

    wave_type / bands_direction / rings_direction / profile: codes of :data:`WAVE_TYPES`,
    :data:`WAVE_BANDS_DIRECTIONS`, :data:`WAVE_RINGS_DIRECTIONS`, :data:`WAVE_PROFILES`.
    """
    return _wave_texture(np.float64(x), np.float64(y), np.float64(z), np.int64(wave_type), np.int64(bands_direction),
                         np.int64(rings_direction), np.int64(profile), np.float64(scale), np.float64(distortion),
                         np.float64(detail), np.float64(detail_scale), np.float64(detail_roughness),
                         np.float64(phase))


@njit(**JIT)
def brick_texture(x, y, z, scale, mortar_size, mortar_smooth, bias, brick_width, row_height, offset_amount,
                  offset_frequency, squash_amount, squash_frequency):
    """Brick Texture node -> (fac, tint).

    fac: the Fac output (1 in the mortar, smooth to 0 across ``mortar_smooth``); tint: the brick's
    Color1 -> Color2 blend.  The Color output is :func:`brick_color` (fac, tint, Color1, Color2, Mortar).
    offset_frequency / squash_frequency are the node's integer properties (offset / squash only
    apply when both are non-zero, as in Cycles).  z is unused (the node is 2D).
    """
    return _brick_texture(np.float64(x), np.float64(y), np.float64(z), np.float64(scale), np.float64(mortar_size),
                          np.float64(mortar_smooth), np.float64(bias), np.float64(brick_width),
                          np.float64(row_height), np.float64(offset_amount), np.int64(offset_frequency),
                          np.float64(squash_amount), np.int64(squash_frequency))


@njit(**JIT)
def magic_texture(x, y, z, depth, scale, distortion):
    """Magic Texture node -> (fac, r, g, b); depth: the node's turbulence_depth (0-10); fac = mean of r, g, b."""
    return _magic_texture(np.float64(x), np.float64(y), np.float64(z), np.int64(depth), np.float64(scale),
                          np.float64(distortion))


@njit(**JIT)
def white_noise_texture(x, y, z, w, dims):
    """White Noise Texture node -> (value, r, g, b): hashes of the float32 bits of the inputs (value == r)."""
    return _white_noise_texture(np.float64(x), np.float64(y), np.float64(z), np.float64(w), np.int64(dims))
