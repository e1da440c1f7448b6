"""Float64 triangle maths shared by both ray-casting backends.

Everything here is exact double precision and vectorised over rays:

* :func:`ray_triangle` - Moeller-Trumbore for ray/triangle *pairs* (used by the
  embree backend to refine a float32 hit, and by the numpy backend with
  broadcasting over all triangles).
* :func:`world_to_object` - per-ray inverse of an instance transform at each
  ray's own time (closed-form 3x3 inverse, no ``np.linalg.inv`` per ray).
* :func:`triangles_at` - object-space corners of chosen triangles of a
  (possibly deforming) mesh at per-ray times.
* :class:`InstanceShading` - hit point data (geometric normal, shading normal,
  material) of one instance at the ray's time, in world space.
* :func:`scene_scale`, :func:`tmin_of` - the self-intersection guard.
* :func:`instance_offsets`, :func:`offset_lengths` - how far secondary rays
  start off the surface they leave (local to the object hit).
* :func:`swept_bounds` - world box of an instance over the whole shutter.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "TMIN_REL", "ray_triangle", "cross", "world_to_object", "triangles_at",
    "InstanceShading", "normals_at", "scene_scale", "tmin_of", "ray_guard", "segment_of",
    "swept_bounds", "apply_affine", "apply_linear", "MotionKeys", "normal_matrix",
    "OFFSET_REL", "OFFSET_POS", "GUARD_FRACTION", "instance_offsets", "offset_lengths",
]

# Self-intersection guard: a ray never reports a hit closer than
# TMIN_REL * scene_scale (a distance in scene units, scene_scale = diagonal of
# the scene bounds over the whole shutter).  Callers still offset origins
# along the normal; this only stops a ray re-hitting the surface it left.
TMIN_REL = 1e-6

# Secondary-ray origin offset along the geometric normal (a distance, per hit):
# OFFSET_REL x the size of the object hit + OFFSET_POS x the hit point's largest
# coordinate (float32 resolution there), so a huge or far object elsewhere in the
# scene does not push every ray off its surface (docs/raycast.md).
OFFSET_REL = 1e-5
OFFSET_POS = 1e-7
# A secondary ray started eps off a surface ignores hits closer than GUARD_FRACTION * eps
# (its own guard, :func:`ray_guard`): local like eps, so thin geometry near the surface still
# counts in a scene with a far object.
GUARD_FRACTION = 0.5


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (..., 3) x (..., 3) -> (..., 3); faster than np.cross."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def ray_triangle(o, d, v0, v1, v2):
    """Moeller-Trumbore ray/triangle test, float64, broadcasting over leading axes.

    Parameters
    ----------
    o, d : (..., 3) ray origins and directions (t in units of |d|).
    v0, v1, v2 : (..., 3) triangle corners (broadcast against o, d).

    Returns
    -------
    t, u, v : (...) ray parameter of the plane crossing and barycentrics
        (point = (1-u-v) v0 + u v1 + v v2); ``inf`` / 0 where the ray is
        parallel to the plane or the triangle has zero area.  No inside test:
        callers decide with ``u >= 0, v >= 0, u + v <= 1``.
    """
    e1 = v1 - v0
    e2 = v2 - v0
    p = cross(d, e2)
    det = _dot(e1, p)
    ok = det != 0.0
    inv_det = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = o - v0
    u = _dot(s, p) * inv_det
    q = cross(s, e1)
    v = _dot(d, q) * inv_det
    t = np.where(ok, _dot(e2, q) * inv_det, np.inf)
    return t, u, v


def segment_of(times_knots: np.ndarray, t: np.ndarray):
    """Segment index i (n,) and fraction a (n,) of times t in knots (K,), clamped outside."""
    K = times_knots.shape[0]
    i = np.clip(np.searchsorted(times_knots, t, side="right") - 1, 0, K - 2)
    t0, t1 = times_knots[i], times_knots[i + 1]
    a = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return i, a


def _inverse3(M: np.ndarray) -> np.ndarray:
    """Closed-form inverse of (n, 3, 3) matrices via cofactors."""
    a, b, c = M[:, 0, 0], M[:, 0, 1], M[:, 0, 2]
    d, e, f = M[:, 1, 0], M[:, 1, 1], M[:, 1, 2]
    g, h, i = M[:, 2, 0], M[:, 2, 1], M[:, 2, 2]
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    inv = np.empty_like(M)
    inv[:, 0, 0], inv[:, 1, 0], inv[:, 2, 0] = A, B, C
    inv[:, 0, 1], inv[:, 1, 1], inv[:, 2, 1] = c * h - b * i, a * i - c * g, b * g - a * h
    inv[:, 0, 2], inv[:, 1, 2], inv[:, 2, 2] = b * f - c * e, c * d - a * f, a * e - b * d
    with np.errstate(divide="ignore", invalid="ignore"):   # singular (zero scale): inf / NaN rays miss
        return inv / det[:, None, None]


def normal_matrix(M3: np.ndarray) -> np.ndarray:
    """(3, 3) map of object-space normals to world-space normal directions for M3 (3, 3).

    The cofactor matrix ``C = det(M) M^-T`` times sign(det): the inverse
    transpose up to a positive factor, and still defined when a zero scale
    makes M singular (a flattened object keeps its normal).
    """
    m0, m1, m2 = M3[:, 0], M3[:, 1], M3[:, 2]
    C = np.column_stack([np.cross(m1, m2), np.cross(m2, m0), np.cross(m0, m1)])
    det = float(np.dot(m0, C[:, 0]))
    return C * (-1.0 if det < 0 else 1.0)


class ExactCastPart:
    """``occluded`` and ``shade`` for parts whose ``cast`` is exact at each ray's time.

    A part using it sets ``self.index`` (its instance) and ``self.shading``
    (an :class:`InstanceShading`) and defines ``cast(o, d, times, t0, t1) ->
    (t, prim, u, v)``.  Used by the numpy parts and by embree's deforming part.
    """

    def occluded(self, o, d, times, t0, t1):
        return np.isfinite(self.cast(o, d, times, t0, t1)[0])

    def shade(self, times, p, u, v):
        ng, ns, mat = self.shading.shade(p, u, v, times)
        return np.full(p.shape[0], self.index, np.int32), p.astype(np.int32), ng, ns, mat


def baked_normals(Vo: np.ndarray, F: np.ndarray, M: np.ndarray, corner_normals) -> tuple[np.ndarray, np.ndarray]:
    """World-space normals of a static instance baked into world space.

    Vo : (V, 3) object-space vertices; F : (F, 3) triangles; M : (4, 4) object-to-world;
    corner_normals : (F, 3, 3) object-space shading normals or None.
    Returns ng (F, 3) unit geometric normals (the object winding decides the side,
    mapped by the cofactor matrix so a zero scale still gives a normal) and
    ns_corners (F, 3, 3) world shading normals per corner (not normalised; ng where
    the mesh has none).
    """
    AT = normal_matrix(M[:3, :3])
    Po = Vo[F]
    n_w = cross(Po[:, 1] - Po[:, 0], Po[:, 2] - Po[:, 0]) @ AT.T
    L = np.linalg.norm(n_w, axis=1, keepdims=True)
    n_w = n_w / np.where(L > 0, L, 1.0)
    if corner_normals is not None:
        ns = np.asarray(corner_normals, dtype=np.float64) @ AT.T
    else:
        ns = np.repeat(n_w[:, None, :], 3, axis=1)
    return n_w, ns


def world_to_object(transform, times: np.ndarray):
    """World-to-object affine maps of an instance at each ray's time.

    Parameters
    ----------
    transform : MotionTransform (object-to-world).
    times : (n,) normalised shutter times.

    Returns
    -------
    A : (n, 3, 3) or (1, 3, 3) for a static transform; b : same leading shape x 3.
        ``x_obj = A @ x_world + b``; directions map with ``A`` alone (never
        renormalised, so t is the same in both spaces).

    Same interpolation as :meth:`MotionTransform.at` (translation lerp, rotation
    slerp, stretch lerp; ``M = T R S`` so ``M^-1 x = S^-1 R^T (x - T)``), written
    out per matrix entry because ``at`` + ``inv`` costs about 1.3 us per ray.
    """
    if transform.is_static:
        M = transform.matrices[0]
        A = _inverse3(M[None, :3, :3])          # cofactors: np.linalg.inv costs ms per call here
        return A, -(A[0] @ M[:3, 3])[None]
    # Decomposed keys of the transform (translation, unit quaternion, stretch)
    T_k, Q_k, S_k = transform._T, transform._Q, transform._S
    i, a = segment_of(transform.times, times)
    if np.all(Q_k == Q_k[:1]) and np.all(S_k == S_k[:1]):
        # Pure translation (the common case): A is constant, only b moves
        A = _inverse3(transform.matrices[:1, :3, :3])
        T = T_k[i] + a[:, None] * (T_k[i + 1] - T_k[i])
        return A, -(T @ A[0].T)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _inverse_from_keys(T_k, Q_k, S_k, i, a)


def _inverse_from_keys(T_k, Q_k, S_k, i, a, i1=None):
    """World-to-object A (n, 3, 3), b (n, 3) between keys i and i+1 (n,) at fractions a (n,).

    T_k (K, 3) translations, Q_k (K, 4) unit quaternions (w, x, y, z), S_k
    (K, 3, 3) symmetric stretches of decomposed keys ``M = T R S``; ``i1``
    (default i + 1) the second key of each pair.
    """
    i1 = i + 1 if i1 is None else i1
    # Rotation: slerp along the shorter arc, component arrays (n,) throughout
    q0 = [Q_k[i, c] for c in range(4)]
    q1 = [Q_k[i1, c] for c in range(4)]
    cos_theta = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3]
    sign = np.where(cos_theta < 0, -1.0, 1.0)
    theta = np.arccos(np.minimum(np.abs(cos_theta), 1.0))
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-6
    safe = np.where(small, 1.0, sin_theta)
    w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / safe)
    w1 = np.where(small, a, np.sin(a * theta) / safe) * sign
    w, x, y, z = (w0 * q0[c] + w1 * q1[c] for c in range(4))
    norm = 1.0 / np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * norm, x * norm, y * norm, z * norm
    # R^T from the quaternion (row-major entries)
    RT = [[1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)],
          [2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)],
          [2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)]]
    # Stretch: lerp the symmetric S, invert by cofactors
    lerp = lambda K, r, c: K[i, r, c] + a * (K[i1, r, c] - K[i, r, c])
    s00, s01, s02 = lerp(S_k, 0, 0), lerp(S_k, 0, 1), lerp(S_k, 0, 2)
    s11, s12, s22 = lerp(S_k, 1, 1), lerp(S_k, 1, 2), lerp(S_k, 2, 2)
    c00, c01, c02 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    c11, c12, c22 = s00 * s22 - s02 * s02, s01 * s02 - s00 * s12, s00 * s11 - s01 * s01
    inv_det = 1.0 / (s00 * c00 + s01 * c01 + s02 * c02)
    Si = [[c00 * inv_det, c01 * inv_det, c02 * inv_det],
          [c01 * inv_det, c11 * inv_det, c12 * inv_det],
          [c02 * inv_det, c12 * inv_det, c22 * inv_det]]
    # A = S^-1 R^T, b = -A T
    A = np.empty((a.shape[0], 3, 3))
    for r in range(3):
        for c in range(3):
            A[:, r, c] = Si[r][0] * RT[0][c] + Si[r][1] * RT[1][c] + Si[r][2] * RT[2][c]
    T = [T_k[i, c] + a * (T_k[i1, c] - T_k[i, c]) for c in range(3)]
    b = -np.stack([A[:, r, 0] * T[0] + A[:, r, 1] * T[1] + A[:, r, 2] * T[2] for r in range(3)], axis=1)
    return A, b


class MotionKeys:
    """Decomposed keys of several moving transforms, stacked, for per-(ray, instance) inverses.

    ``world_to_object(j, times)`` gives the inverse of transform ``j[k]`` at
    ``times[k]`` for every pair k in one vectorised pass (instances of one
    mesh share a single pass and a single embree call).
    """

    def __init__(self, transforms: list):
        self.T = np.concatenate([tr._T for tr in transforms])
        self.Q = np.concatenate([tr._Q for tr in transforms])
        self.S = np.concatenate([tr._S for tr in transforms])
        self.knots = np.concatenate([tr.times for tr in transforms])
        counts = np.array([tr.times.shape[0] for tr in transforms])
        self.first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.last = self.first + counts - 1
        owner = np.repeat(np.arange(len(transforms)), counts)
        # Knots of transform j shifted by j * W: one searchsorted serves every transform
        self.W = float(self.knots.max() - self.knots.min()) + 1.0
        self.shifted = self.knots + self.W * owner

    def world_to_object(self, j: np.ndarray, times: np.ndarray):
        """A (m, 3, 3), b (m, 3) of transforms j (m,) at times (m,)."""
        f, l = self.first[j], self.last[j]
        tq = np.clip(times, self.knots[f], self.knots[l])
        i = np.clip(np.searchsorted(self.shifted, tq + self.W * j, side="right") - 1, f, np.maximum(l - 1, f))
        i1 = np.minimum(i + 1, l)
        span = self.knots[i1] - self.knots[i]
        a = np.clip(np.divide(times - self.knots[i], span, out=np.zeros_like(times), where=span > 0), 0.0, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return _inverse_from_keys(self.T, self.Q, self.S, i, a, i1)


def apply_affine(A: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A (n|1, 3, 3) @ x (n, 3) + b (n|1, 3) -> (n, 3)."""
    if A.shape[0] == 1:
        return x @ A[0].T + b
    return np.einsum("nij,nj->ni", A, x) + b


def apply_linear(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A (n|1, 3, 3) @ x (n, 3) -> (n, 3)."""
    if A.shape[0] == 1:
        return x @ A[0].T
    return np.einsum("nij,nj->ni", A, x)


def triangles_at(mesh, prim: np.ndarray, times: np.ndarray, V: np.ndarray | None = None) -> np.ndarray:
    """Object-space corners (n, 3, 3) float64 of triangles ``prim`` (n,) at times (n,).

    Rigid meshes ignore ``times``; deforming meshes interpolate their vertex
    steps linearly (clamped outside the first/last step).  ``V``: the mesh's
    vertices already as float64 (saves converting them on every call).
    """
    tri = np.asarray(mesh.triangles)[prim]
    V = np.asarray(mesh.vertices, dtype=np.float64) if V is None else V
    if not mesh.is_deforming:
        V = V[0] if V.ndim == 3 else V
        return V[tri]
    i, a = segment_of(np.asarray(mesh.vertex_times, dtype=np.float64), times)
    P0 = V[i[:, None], tri]
    P1 = V[i[:, None] + 1, tri]
    return P0 + a[:, None, None] * (P1 - P0)


def normals_at(mesh, N: np.ndarray, prim: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Object-space corner normals (n, 3, 3) float64 of triangles ``prim`` (n,) at times (n,) of a
    deforming mesh with normals per vertex step N (K, F, 3, 3) (float32 or float64): linear between
    the steps of ``mesh.vertex_times`` (clamped outside), as :func:`triangles_at` does positions;
    not normalised."""
    i, a = segment_of(np.asarray(mesh.vertex_times, dtype=np.float64), times)
    N0, N1 = N[i, prim].astype(np.float64), N[i + 1, prim].astype(np.float64)
    return N0 + a[:, None, None] * (N1 - N0)


def _normalize(n: np.ndarray) -> np.ndarray:
    L = np.sqrt(_dot(n, n))
    return n / np.where(L > 0, L, 1.0)[..., None]


class InstanceShading:
    """World-space hit data of one instance at per-ray times.

    Normals map object -> world with the inverse transpose of the transform at
    the ray's time.  The object-space winding decides ``ng``'s side, so a
    mirrored (negative-scale) object keeps its outside (Blender's convention).
    A deforming mesh's corner normals (per vertex step, :attr:`stpm_core.scene.Mesh.normal_keys`)
    are interpolated to the ray's time like its positions (:func:`normals_at`), then blended
    across the triangle and normalised.
    """

    def __init__(self, mesh, transform):
        self.mesh = mesh
        self.transform = transform
        self.material_ids = np.asarray(mesh.material_ids, dtype=np.int32)
        self.V = np.asarray(mesh.vertices, dtype=np.float64)
        # Static transform: one normal matrix, defined even for a zero scale
        self.N_static = None
        if transform is not None and transform.is_static:
            self.N_static = normal_matrix(transform.matrices[0, :3, :3])[None]
        # Corner normals: (F, 3, 3) shared by every time, or (K, F, 3, 3) per vertex step
        self.normals = self.normal_steps = None
        keys = mesh.normal_keys
        if keys is not None and mesh.is_deforming and keys.shape[0] > 1:
            self.normal_steps = np.ascontiguousarray(keys, dtype=np.float32)   # 36 B per triangle per step
        elif keys is not None:
            self.normals = np.asarray(keys[0], dtype=np.float64)

    def shade(self, prim, u, v, times, A=None):
        """Normals and material for hits (n,) -> ng (n, 3), ns (n, 3), material (n,).

        ``A`` is the world-to-object linear part at the hit times if the caller
        already has it ((n, 3, 3) or (1, 3, 3)).
        """
        if A is None and self.N_static is not None:
            AT = self.N_static
        else:
            if A is None:
                A, _ = world_to_object(self.transform, times)
            AT = np.swapaxes(A, 1, 2)
        P = triangles_at(self.mesh, prim, times, self.V)
        n_obj = cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
        ng = _normalize(apply_linear(AT, n_obj))
        if self.normals is None and self.normal_steps is None:
            ns = ng.copy()
        else:
            N = self.normals[prim] if self.normal_steps is None else \
                normals_at(self.mesh, self.normal_steps, prim, times)
            n_s = (1 - u - v)[:, None] * N[:, 0] + u[:, None] * N[:, 1] + v[:, None] * N[:, 2]
            ns = _normalize(apply_linear(AT, n_s))
            bad = ~np.any(ns != 0, axis=1)
            ns[bad] = ng[bad]
        return ng, ns, self.material_ids[prim]


def scene_scale(scene) -> float:
    """Diagonal of the scene bounds over the shutter (scene units; 1 if empty)."""
    lo, hi = scene.bounds()
    s = float(np.linalg.norm(hi - lo))
    return s if np.isfinite(s) and s > 0 else 1.0


def instance_offsets(scene) -> np.ndarray:
    """Per-instance offset length (n_instances,) = OFFSET_REL x the object's own size (scene units).

    Size = diagonal of the mesh's object-space vertex box times the transform's largest axis
    scale over its keys, so motion (a box sliding 1 km) does not count, only the object;
    floored at 1e-12 x the scene scale so that a degenerate object still gets a positive offset.
    """
    cache = scene.frozen_cache() if hasattr(scene, "frozen_cache") else None
    if cache is not None and "instance_offsets" in cache:
        return cache["instance_offsets"].copy()
    floor = 1e-12 * scene_scale(scene)
    out = np.empty(len(scene.instances))
    for i, inst in enumerate(scene.instances):
        lo, hi = scene.meshes[inst.mesh].vertex_bounds()
        M = inst.transform.matrices                              # (K, 4, 4)
        axis_scale = np.sqrt(np.max(np.sum(M[:, :3, :3] ** 2, axis=1)))   # largest column norm
        size = float(np.linalg.norm(hi - lo) * axis_scale)
        out[i] = OFFSET_REL * (size if np.isfinite(size) and size > floor else floor)
    if cache is not None:
        cache["instance_offsets"] = out.copy()
    return out


def offset_lengths(inst_offset: np.ndarray, instance: np.ndarray, position: np.ndarray) -> np.ndarray:
    """Origin offsets (n,) for hits on ``instance`` (n,) (all >= 0) at ``position`` (n, 3): the
    object's offset (:func:`instance_offsets`) + OFFSET_POS x the largest |coordinate| of the hit."""
    return inst_offset[instance] + OFFSET_POS * np.max(np.abs(position), axis=1, initial=0.0)


def tmin_of(dirs: np.ndarray, scale: float, guard: np.ndarray | None = None) -> np.ndarray:
    """Per-ray guard (n,) in units of |dir|: TMIN_REL * scale / |dir|, or guard (n,) (a distance
    per ray, see :func:`ray_guard`) / |dir|."""
    L = np.sqrt(_dot(dirs, dirs))
    g = TMIN_REL * scale if guard is None else guard
    return g / np.where(L > 0, L, 1.0)


def ray_guard(scale: float, guard) -> np.ndarray:
    """Guard distances as the casters use them: (1,) = TMIN_REL * scale for every ray (guard None),
    else each ray's own guard (n,), never more than TMIN_REL * scale.

    Callers that offset a ray's origin by e off the surface it leaves pass about e / 2: the
    surface is then behind the origin, and a float32 re-hit of it is refined to t <= 0 and
    re-cast, so the guard can be local where the global one (1e-6 x the scene diagonal) would
    skip thin geometry near the surface in a scene with a far object (docs/raycast.md).
    """
    cap = TMIN_REL * scale
    if guard is None:
        return np.array([cap])
    return np.ascontiguousarray(np.minimum(np.asarray(guard, np.float64), cap))


def swept_bounds(mesh, transform):
    """World bounds (lo, hi) of an instance over the whole shutter, padded by 1e-6 of the size."""
    V = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    lo, hi = transform.bounds_of(V.min(0), V.max(0))
    pad = 1e-6 * float(np.linalg.norm(hi - lo)) + 1e-300
    if not transform.is_static:
        pad += 0.01 * float(np.linalg.norm(hi - lo))   # rotation arcs between the 33 samples
    return lo - pad, hi + pad
