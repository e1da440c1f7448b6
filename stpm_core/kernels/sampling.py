"""Scalar helpers of the light kernels (numba, one row at a time): vectors, warps, frames, light shapes.

:mod:`.lights` (next-event sampling, shapes seen along rays) and :mod:`.emission` (photons) are
built from these; neither defines a helper of its own that the other needs.

Conventions
-----------
* Vectors are 3-tuples of floats, points of the unit disc 2-tuples; nothing allocates.  ``M`` is
  a (4, 4) object-to-world matrix (:func:`column` j of its upper 3 x 4; j = 3 the translation).
* Warps take two uniforms u0, u1 in [0, 1) and give the same float operations, in the same
  order, as the numpy warps of :mod:`stpm_core.sampling` (``concentric_disk``,
  ``cosine_hemisphere``, ``uniform_sphere``, ``uniform_cone``): local directions about +z,
  turned into the world about a unit axis by :func:`to_world` (Duff et al.'s basis,
  ``sampling.orthonormal_basis``).
* Two summation orders of a 3-component dot product, so that the kernels reproduce the numpy
  code they replaced bit for bit (the numpy code is kept as the test oracles
  ``tests/oracles/lights_numpy.py`` and ``emission_numpy.py``; the tests ask for 1e-9):
  :func:`dot` adds the products in index order, as ``np.sum(a * b, axis=-1)``,
  ``np.linalg.norm`` and ``np.einsum("ij,ij->i", a, b)`` of a strided operand (a matrix column
  such as ``M[:, :3, 2]``) do; :func:`edot` adds them as that einsum does over contiguous rows
  of 3 (numpy 1.26, SIMD pairs): (a0 b0 + a2 b2) + a1 b1.  Every call site uses the order of
  the numpy expression it stands for; :func:`normalize` (einsum order, ``lights._normalize``)
  and :func:`unit` (index order) likewise.  A numpy whose einsum or sin / cos differ would move
  results by an ulp.
* Light helpers read a light's parameter row ``prm`` (columns ``P_*`` of :mod:`.light_params`).

Compile policy (measured 2026-12-01, docs/rendering.md "Compile time"): helpers are ordinary
compiled functions (``JIT``), compiled once and linked into each kernel that calls it; LLVM
inlines the small ones there (checked: no call is left in the machine code), so numba-level
inlining (``inline="always"``) bought no speed and cost compile time: without it a render's cold
compile is about 18 % shorter (64.6 -> 53.0 s, one run each) at the same tracer speed and
bit-identical images.  The exceptions (``JIT_INLINE``) are the indexing helpers called with
constant indices (``vec3``, ``column``, ``_mesh_corner``; and ``closure.closure_row``, called
with int32 and int64 ids): compiled on their own, numba would specialise them once per literal.  Big per-hit functions (the BSDF's eval / sample, an area light's sample)
are not inlined by LLVM; a loop that merely contains a call to one, in a branch it never takes,
runs about twice slower per row (``paths.nee_light`` keeps such calls in loops of their own).
numba's on-disk cache of a kernel is invalidated by edits of the kernel's own file only, not of
the functions it calls from other files: ``numba_probe.invalidate_stale_caches`` (run at
import) touches every kernel source when any of them changed.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .light_params import P_ANGLE, P_COLOR, P_COS_HALF, P_POWER, P_SHAPE, P_SIZE, P_SIZE_Y, P_SMOOTH, S_DISK, S_ELLIPSE

__all__ = ["JIT", "JIT_INLINE", "TWO_PI", "INV_4PI", "dot", "edot", "cross", "normalize", "unit", "column",
           "vec3", "row3", "pose_buffer", "load_pose", "sub", "add", "neg", "scale", "madd", "plane_point", "clip", "sign", "basis", "to_world",
           "concentric_disk", "cosine_hemisphere", "uniform_sphere", "uniform_cone", "axis_or_z",
           "one_minus_cos_from_sin2", "sun_cone", "light_axis", "intensity", "spot_attenuation", "area_shape", "area_point",
           "search_right", "mesh_point", "mesh_triangle", "mesh_choice", "mesh_choices"]

JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
# Only for tiny indexing helpers called with constant indices or ids of several integer types:
# compiled on their own, numba would make one copy per literal index / per integer type.
JIT_INLINE = dict(JIT, inline="always")

TWO_PI = 2.0 * np.pi
INV_4PI = 1.0 / (4.0 * np.pi)                    # lights.INV_4PI


# ----------------------------------------------------------------------------
# Vectors (3-tuples)
# ----------------------------------------------------------------------------
@njit(**JIT)
def dot(a, b):
    """a . b summed in index order (``np.sum(a * b, axis=-1)``, ``np.linalg.norm``, einsum of a column)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(**JIT)
def edot(a, b):
    """a . b summed as ``np.einsum("ij,ij->i", a, b)`` sums contiguous rows: (a0 b0 + a2 b2) + a1 b1."""
    return a[0] * b[0] + a[2] * b[2] + a[1] * b[1]


@njit(**JIT)
def cross(a, b):
    """a x b (numpy.cross's formula)."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(**JIT)
def normalize(v):
    """(unit v, |v|) as ``lights._normalize``: |v| = sqrt(edot(v, v)), v / max(|v|, 1e-300); zero stays zero."""
    length = math.sqrt(edot(v, v))
    s = max(length, 1e-300)
    return (v[0] / s, v[1] / s, v[2] / s), length


@njit(**JIT)
def unit(v):
    """(unit v, |v|) with |v| summed in index order (``np.linalg.norm``; ``lights._normalize`` of a
    matrix column, as ``LightSet._frame`` does), v / max(|v|, 1e-300)."""
    length = math.sqrt(dot(v, v))
    s = max(length, 1e-300)
    return (v[0] / s, v[1] / s, v[2] / s), length


@njit(**JIT_INLINE)
def column(M, j):
    """Column j (3-tuple) of the upper 3 x 4 of M (j = 3: the translation)."""
    return (M[0, j], M[1, j], M[2, j])


@njit(**JIT_INLINE)
def vec3(a, k):
    """(a[k], a[k + 1], a[k + 2]) of a 1-D array (a parameter row's 3 columns from k, a row of an (n, 3))."""
    return (a[k], a[k + 1], a[k + 2])


@njit(**JIT_INLINE)
def row3(A, r):
    """(A[r, 0], A[r, 1], A[r, 2]) of an (n, 3) array, read in place.  In a per-row loop, prefer this
    to ``vec3(A[r], 0)``: every array view a loop makes (``A[r]``, ``poses[k]``, an array taken
    out of a tuple) takes and drops a reference to its parent, two atomic operations per row that
    the compiler leaves in (docs/rendering.md, "Where the tracer's time goes")."""
    return (A[r, 0], A[r, 1], A[r, 2])


@njit(**JIT)
def pose_buffer(poses):
    """A (4, 4) copy of poses[0]: the matrix a per-row loop hands to per-row functions, refilled
    with :func:`load_pose` when poses has one matrix per row (a view ``poses[k]`` per row would
    cost two atomic reference-count operations per row, see :func:`row3`)."""
    M = np.empty((4, 4))
    for a in range(4):
        for b in range(4):
            M[a, b] = poses[0, a, b]                 # (not load_pose(poses, 0, M): a literal 0 would compile a second signature)
    return M


@njit(**JIT)
def load_pose(poses, k, M):
    """M (4, 4) = poses[k], element by element (no view)."""
    for a in range(4):
        for b in range(4):
            M[a, b] = poses[k, a, b]


@njit(**JIT)
def sub(a, b):
    """a - b."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(**JIT)
def add(a, b):
    """a + b."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(**JIT)
def neg(a):
    """-a."""
    return (-a[0], -a[1], -a[2])


@njit(**JIT)
def scale(a, s):
    """a s (each component times the scalar s)."""
    return (a[0] * s, a[1] * s, a[2] * s)


@njit(**JIT)
def madd(a, s, b):
    """a + s b."""
    return (a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2])


@njit(**JIT)
def plane_point(c, x, ex, y, ey):
    """c + x ex + y ey, added left to right (a point of a plane spanned by ex, ey through c)."""
    return (c[0] + x * ex[0] + y * ey[0], c[1] + x * ex[1] + y * ey[1], c[2] + x * ex[2] + y * ey[2])


@njit(**JIT)
def clip(x, lo, hi):
    """np.clip(x, lo, hi) for one float."""
    return min(max(x, lo), hi)


@njit(**JIT)
def sign(x):
    """np.sign(x): -1, 0 or 1 (nan stays nan)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x * 0.0


# ----------------------------------------------------------------------------
# Frames and warps (stpm_core.sampling, one row)
# ----------------------------------------------------------------------------
@njit(**JIT)
def basis(n):
    """(tangent, bitangent) about the unit vector n (``sampling.orthonormal_basis``, Duff et al. 2017)."""
    x, y, z = n[0], n[1], n[2]
    sg = 1.0 if z >= 0.0 else -1.0
    a = -1.0 / (sg + z)
    b = x * y * a
    return (1.0 + sg * x * x * a, sg * b, -sg * x), (b, sg + y * y * a, -y)


@njit(**JIT)
def to_world(l, n):
    """Local direction l (z = the unit axis n) in the world: l0 t + l1 b + l2 n (``sampling.to_world``)."""
    t, b = basis(n)
    return (l[0] * t[0] + l[1] * b[0] + l[2] * n[0], l[0] * t[1] + l[1] * b[1] + l[2] * n[1],
            l[0] * t[2] + l[1] * b[2] + l[2] * n[2])


@njit(**JIT)
def concentric_disk(u0, u1):
    """Uniform point (x, y) of the unit disc (Shirley-Chiu; ``sampling.concentric_disk``)."""
    a = 2.0 * u0 - 1.0
    b = 2.0 * u1 - 1.0
    if abs(a) > abs(b):
        r = a
        phi = 0.25 * np.pi * (b / (1.0 if a == 0.0 else a))
    else:
        r = b
        phi = 0.5 * np.pi - 0.25 * np.pi * (a / (1.0 if b == 0.0 else b))
    return r * math.cos(phi), r * math.sin(phi)


@njit(**JIT)
def cosine_hemisphere(u0, u1):
    """Cosine-distributed local direction about +z, pdf cos / pi (``sampling.cosine_hemisphere``)."""
    x, y = concentric_disk(u0, u1)
    return x, y, math.sqrt(max(0.0, 1.0 - (x * x + y * y)))


@njit(**JIT)
def uniform_sphere(u0, u1):
    """Uniform direction on the unit sphere, pdf 1 / (4 pi) (``sampling.uniform_sphere``)."""
    z = 1.0 - 2.0 * u0
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = TWO_PI * u1
    return r * math.cos(phi), r * math.sin(phi), z


@njit(**JIT)
def uniform_cone(u0, u1, cos_max):
    """Uniform local direction about +z with cos(theta) >= cos_max (``sampling.uniform_cone``)."""
    cos_t = 1.0 - u0 * (1.0 - cos_max)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    phi = TWO_PI * u1
    return sin_t * math.cos(phi), sin_t * math.sin(phi), cos_t


@njit(**JIT)
def axis_or_z(v):
    """(axis, ok): v where edot(v, v) > 0.5, else +Z, and ok = 1.0 / 0.0 (the oracles' ``_axis_or_z``).

    A light whose transform has a zero scale along Z has no direction (:func:`light_axis` is then
    zero): its rows get +Z, so every direction stays unit, and zero weight or power (times ok).
    """
    if edot(v, v) > 0.5:
        return v, 1.0
    return (0.0, 0.0, 1.0), 0.0


@njit(**JIT)
def one_minus_cos_from_sin2(sin2):
    """1 - sqrt(1 - sin^2) without cancellation for small angles (sin^2 clipped to [0, 1])."""
    sin2 = clip(sin2, 0.0, 1.0)
    return sin2 / (1.0 + math.sqrt(1.0 - sin2))


@njit(**JIT)
def sun_cone(prm):
    """(cos_half, Omega, norm) of a SUN of angular diameter ``angle`` (its parameter row prm):
    cos_half = cos(angle / 2); Omega = 2 pi (1 - cos_half) sr, the cone next-event estimation and
    photons draw directions from uniformly (density 1 / Omega); norm = 2 / (1 + cos_half) =
    Omega / (pi sin^2(angle / 2)), Cycles' normalisation (its ``Light::area`` of a sun, pi
    sin^2(angle / 2)): the sun's radiance is color S norm / Omega = color S / (pi sin^2(angle / 2)),
    so a surface facing it receives exactly S.  Angle 0: cos_half = 1, Omega = 0, norm = 1."""
    cos_half = math.cos(0.5 * prm[P_ANGLE])
    return cos_half, TWO_PI * (1.0 - cos_half), 2.0 / (1.0 + cos_half)


# ----------------------------------------------------------------------------
# Light geometry (parameter rows of light_params, one pose M)
# ----------------------------------------------------------------------------
@njit(**JIT)
def light_axis(M):
    """The light's unit Z axis, M's Z column normalised (``LightSet._frame``: scale removed; zero
    for a zero Z scale).  The light shines along -Z; a SUN sits toward +Z."""
    Z, _ = unit(column(M, 2))
    return Z


@njit(**JIT)
def intensity(prm):
    """POINT / SPOT radiant intensity I = color P / (4 pi) W/sr (``LightSet.intensity``)."""
    power = prm[P_POWER]
    return (prm[P_COLOR] * power * INV_4PI, prm[P_COLOR + 1] * power * INV_4PI, prm[P_COLOR + 2] * power * INV_4PI)


@njit(**JIT)
def spot_attenuation(prm, cos_axis):
    """Spot mask at cosine cos_axis to the spot axis (``lights.spot_attenuation``): 0 outside the
    cone (``P_COS_HALF``), smoothstep over the blend band ``P_SMOOTH`` in cosine, 1 inside."""
    x = cos_axis - prm[P_COS_HALF]
    smooth = prm[P_SMOOTH]
    if smooth <= 0.0:
        return 1.0 if x > 0.0 else 0.0
    if x > 0.0:
        s = clip(x / smooth, 0.0, 1.0)
        return s * s * (3.0 - 2.0 * s)
    return 0.0


@njit(**JIT)
def area_shape(prm, M):
    """AREA light at pose M (scale kept) as ``LightSet._area_shape``: (c, ex, ey, A, n_emit, disk).

    c the centre, ex, ey the half-extent vectors (size / 2 times M's X, Y columns), A the area
    (m^2; pi |ex x ey| for DISK / ELLIPSE, 4 |ex x ey| else), n_emit the unit normal of the plane
    on the side of M's -Z column (``lights.area_light_normal``; zero when -Z lies in the plane or
    the area is zero), disk whether the shape is a disc / ellipse.
    """
    hx = 0.5 * prm[P_SIZE]
    hy = 0.5 * prm[P_SIZE_Y]
    ex = (hx * M[0, 0], hx * M[1, 0], hx * M[2, 0])
    ey = (hy * M[0, 1], hy * M[1, 1], hy * M[2, 1])
    g, A4 = normalize(cross(ex, ey))                 # A4 = |ex x ey| = rectangle area / 4
    side = sign(-dot(g, column(M, 2)))               # +1 where g points along -Z
    shape = int(prm[P_SHAPE])
    disk = shape == S_DISK or shape == S_ELLIPSE
    A = np.pi * A4 if disk else 4.0 * A4
    return column(M, 3), ex, ey, A, scale(g, side), disk


@njit(**JIT)
def area_point(c, ex, ey, disk, u0, u1):
    """Uniform point of an AREA shape (``lights_numpy.area_points``): c + a ex + b ey, (a, b) from
    ``concentric_disk`` (disc / ellipse) or 2u - 1 (square / rectangle)."""
    if disk:
        a, b = concentric_disk(u0, u1)
    else:
        a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0
    return plane_point(c, a, ex, b, ey)


@njit(**JIT)
def search_right(a, x):
    """np.searchsorted(a, x, side='right') for sorted a (n,): the first index i with a[i] > x."""
    lo, hi = 0, a.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(**JIT_INLINE)
def _mesh_corner(M, corners, i, j, v, a):
    """World position of corner v of emitting triangle j: object space at vertex step i (and
    i + 1, weight a, when the mesh deforms), then M x + T, the products summed in einsum's order
    (``lights_numpy.mesh_corners``)."""
    if corners.shape[0] > 1:
        ca = 1.0 - a
        x = ca * corners[i, j, v, 0] + a * corners[i + 1, j, v, 0]
        y = ca * corners[i, j, v, 1] + a * corners[i + 1, j, v, 1]
        z = ca * corners[i, j, v, 2] + a * corners[i + 1, j, v, 2]
    else:
        x, y, z = corners[0, j, v, 0], corners[0, j, v, 1], corners[0, j, v, 2]
    p = (x, y, z)
    return (edot((M[0, 0], M[0, 1], M[0, 2]), p) + M[0, 3], edot((M[1, 0], M[1, 1], M[1, 2]), p) + M[1, 3],
            edot((M[2, 0], M[2, 1], M[2, 2]), p) + M[2, 3])


@njit(**JIT)
def mesh_point(M, steps, corners, q, cdf, t, u0, u1):
    """A point of a MESH light (``lights_numpy.mesh_sample_points``): (point, unit normal, A, j, q_j).

    Triangle j with probability q[j] (u0 picks it by the cdf, then is rescaled to [0, 1) inside
    its interval); corners (``light_params.mesh_arrays``: K steps, object space, or world space
    with an identity M for a static mesh) linear in the normalised time t between vertex steps,
    then M; a uniform point of it, barycentrics (1 - s, s (1 - u1), s u1), s = sqrt(u0'); the
    unit geometric normal e1 x e2 / |e1 x e2| and the triangle's world area A.
    """
    j, qj, b1, b2 = mesh_choice(q, cdf, u0, u1)
    C0, e1, e2 = mesh_triangle(M, steps, corners, j, t)
    nrm, two_A = normalize(cross(e1, e2))
    return plane_point(C0, b1, e1, b2, e2), nrm, 0.5 * two_A, j, qj


@njit(**JIT)
def mesh_triangle(M, steps, corners, j, t):
    """Emitting triangle j of a MESH light at normalised time t: (C0, e1, e2), its first world
    corner and the two edges from it (corners linear in t between vertex steps, then M; as
    :func:`mesh_point` uses them)."""
    K = steps.shape[0]
    i = 0
    a = 0.0
    if K > 1:
        i = min(max(search_right(steps, t) - 1, 0), K - 2)
        a = clip((t - steps[i]) / (steps[i + 1] - steps[i]), 0.0, 1.0)
    C0 = _mesh_corner(M, corners, i, j, 0, a)
    e1 = sub(_mesh_corner(M, corners, i, j, 1, a), C0)
    e2 = sub(_mesh_corner(M, corners, i, j, 2, a), C0)
    return C0, e1, e2


@njit(**JIT)
def mesh_choice(q, cdf, u0, u1):
    """The triangle and barycentrics :func:`mesh_point` makes of (u0, u1): (j, q_j, b1, b2).

    j with probability q[j] (u0 picks it by the cdf, then is rescaled to u0' in [0, 1) inside its
    interval); the point C0 + b1 e1 + b2 e2 with b1 = s (1 - u1), b2 = s u1, s = sqrt(u0') (uniform
    on the triangle; (b1, b2) are the ray caster's hit barycentrics (u, v) of that point).
    """
    F = q.shape[0]
    j = min(search_right(cdf, u0), F - 1)
    qj = q[j]
    lo = cdf[j] - qj
    uu = clip((u0 - lo) / qj, 0.0, 1.0 - 1e-12)
    s = math.sqrt(uu)
    return j, qj, s * (1.0 - u1), s * u1


@njit(**JIT)
def mesh_choices(q, cdf, U, J, B):
    """:func:`mesh_choice` of each row of U (n, 2): J (n,) int64 triangle indices, B (n, 2) (b1, b2)."""
    for k in range(U.shape[0]):
        j, _, b1, b2 = mesh_choice(q, cdf, U[k, 0], U[k, 1])
        J[k] = j
        B[k, 0] = b1
        B[k, 1] = b2


# ----------------------------------------------------------------------------
# Ray origins
# ----------------------------------------------------------------------------
@njit(**JIT)
def offset_origin(p, g, e, w):
    """p moved by e (scene units) along the geometric normal g to the side direction w leaves on:
    p + e g if w . g >= 0, else p - e g (the origin of a ray leaving a surface at p)."""
    side = e if dot(w, g) >= 0.0 else -e
    return p[0] + side * g[0], p[1] + side * g[1], p[2] + side * g[2]
