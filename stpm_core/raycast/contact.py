"""Surfaces in contact: a ray leaving one object where it enters another meets the other.

An object resting on another (a glass cube on a table) has a face that coincides with the other's:
the cube's bottom faces down at the table top's height, the table top faces up.  A ray inside the
cube reaching the table meets both at the same distance, and which one a float32 BVH reports is
an accident of rounding and traversal order.  If it reports the cube's bottom, the ray leaves the
glass and its continuation starts a small offset outside, below the table top (the offset that
keeps it off the face it leaves, ``geometry.offset_lengths``): it then sees what lies under the
table.  Physically the light leaving the glass there meets the table at once.

Rule (``Contacts.resolve``): a hit on the *back* of a face (the ray leaves the solid that face
bounds, ``d . ng > 0``) is replaced by the hit on the *front* of a face of another object that
lies in the same plane (normals opposite, planes within ``tol`` of each other) and contains the
hit point.  The ray then enters the other object's surface there, as if the two solids overlapped
by a hair (a contact without an air gap).  Contacts are found once, over static rigid instances
(``find_contacts``); ``tol`` of a pair is twice the larger of the two objects' origin offsets
(``geometry.instance_offsets`` plus float32 resolution at the point), the distance below which a
ray leaving one face cannot find the other.

Cycles gives this answer for the cube sunk into the table (measured: 1 um; raised 1 um, Cycles sees
an air gap instead); at an exact contact its answer rests on float zeros and the table under the
cube renders black (docs/raycast.md, "Surfaces in contact").  ``occluded`` needs nothing: any hit blocks.
"""
from __future__ import annotations

import numpy as np

from .geometry import OFFSET_POS, InstanceShading, instance_offsets

__all__ = ["Contacts", "find_contacts", "CONTACT_PAIRS_MAX", "warm_up"]

# Normals within this angle of opposite count as one plane (about 0.08 degrees)
COS_OPPOSITE = 1.0 - 1e-6
# Candidate face pairs tested, at most; beyond this (finely subdivided coplanar surfaces facing each
# other) the remaining faces are left out and counted in Contacts.skipped
CONTACT_PAIRS_MAX = 4_000_000
# Normal bins (unit normal components rounded to this) group candidate planes
_NORMAL_BIN = 1e-3


class Contacts:
    """Coincident opposite faces of different static objects, as a lookup by hit triangle.

    keys (k,) int64 sorted: instance * stride + prim of each face that has partners; start (k + 1,)
    its partners' range in the partner arrays: inst (m,), prim (m,), n (m, 3) unit normals, w (m,)
    plane offsets (n . x = w), P (m, 3, 3) world corners.  ``skipped``: faces left out because the
    candidate pairs would pass ``CONTACT_PAIRS_MAX``."""

    def __init__(self, scene, keys, start, inst, prim, P, n, w, stride, skipped=0):
        self.scene = scene
        self.keys, self.start, self.stride = keys, start, stride
        self.inst, self.prim, self.P, self.n, self.w = inst, prim, P, n, w
        self.skipped = skipped
        self._shading: dict[int, InstanceShading] = {}
        # is_contact[first_face[i] + prim]: is triangle prim of instance i a contact face?  (one
        # byte per triangle of the scene; first_face[-1] points at a last, False entry for misses)
        counts = [len(scene.meshes[i.mesh].triangles) for i in scene.instances]
        self.first_face = np.r_[0, np.cumsum(counts)].astype(np.int64)
        self.is_contact = np.zeros(int(self.first_face[-1]) + 1, bool)
        self.is_contact[self.first_face[keys // stride] + keys % stride] = True

    def rebind(self, scene) -> None:
        """Use these contacts with ``scene``, whose static instances are those they were found in
        (a persistent static part reused for the next frame)."""
        self.scene = scene
        self._shading = {}

    def __len__(self) -> int:
        return int(self.keys.size)

    def resolve(self, o, d, times, tmax, hits) -> int:
        """Replace, in place, back-face hits on a face in contact by the partner's front face
        (module docstring); returns how many rays changed.  o, d (n, 3), times, tmax (n,)."""
        if self.keys.size == 0:
            return 0
        # Rows on a contact face (a flag per triangle of the scene), left through its back
        inst = hits.instance
        rows = _back_contact_rows(inst, hits.prim, d, hits.ng, self.first_face, self.is_contact)
        if rows.size == 0:
            return 0
        key = inst[rows].astype(np.int64) * self.stride + hits.prim[rows]
        j = np.searchsorted(self.keys, key)
        # Every (row, partner) pair: the partner's plane along the ray, then inside its triangle
        cnt = self.start[j + 1] - self.start[j]
        r = np.repeat(rows, cnt)
        q = np.repeat(self.start[j] - np.cumsum(np.r_[0, cnt[:-1]]), cnt) + np.arange(cnt.sum())
        dn = np.einsum("ij,ij->i", d[r], self.n[q])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.w[q] - np.einsum("ij,ij->i", o[r], self.n[q])) / dn
        p = o[r] + t[:, None] * d[r]
        P = self.P[q]
        e1, e2, pv = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0], p - P[:, 0]
        d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
        b1, b2 = np.einsum("ij,ij->i", pv, e1), np.einsum("ij,ij->i", pv, e2)
        den = d11 * d22 - d12 * d12
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (d22 * b1 - d12 * b2) / den
            v = (d11 * b2 - d12 * b1) / den
        eps = 1e-9
        ok = ((dn < 0.0) & np.isfinite(t) & (t > 0.0) & (t < tmax[r]) & (u >= -eps) & (v >= -eps)
              & (u + v <= 1.0 + eps))
        if not ok.any():
            return 0
        # First partner that contains the point, per row
        sel = np.flatnonzero(ok)
        r_ok, first = np.unique(r[sel], return_index=True)
        s = sel[first]
        qs = q[s]
        hits.t[r_ok] = t[s]
        hits.position[r_ok] = p[s]
        hits.u[r_ok], hits.v[r_ok] = np.clip(u[s], 0.0, 1.0), np.clip(v[s], 0.0, 1.0)
        hits.instance[r_ok], hits.prim[r_ok] = self.inst[qs], self.prim[qs]
        for i in np.unique(self.inst[qs]):
            m = self.inst[qs] == i
            rr = r_ok[m]
            sh = self._shading.get(int(i))
            if sh is None:
                obj = self.scene.instances[int(i)]
                sh = self._shading[int(i)] = InstanceShading(self.scene.meshes[obj.mesh], obj.transform)
            ng, ns, mat = sh.shade(self.prim[qs][m].astype(np.int64), hits.u[rr], hits.v[rr], times[rr])
            hits.ng[rr], hits.ns[rr], hits.material[rr] = ng, ns, mat
        return int(r_ok.size)


def _back_contact_rows_np(inst, prim, d, ng, first_face, is_contact):
    """(k,) int64 rows whose hit is a contact face (is_contact[first_face[inst] + prim]) seen from
    its back (d . ng > 0); inst -1 (a miss) maps to first_face[-1], a False entry."""
    face = first_face[inst] + np.where(inst >= 0, prim, 0)
    cand = np.flatnonzero(is_contact[face])
    return cand[np.einsum("ij,ij->i", d[cand], ng[cand]) > 0.0]


try:
    from numba import njit as _njit

    def _jit(f):
        return _njit(cache=True, nogil=True)(f)
except ImportError:                                      # pragma: no cover (numba is a dependency)
    def _jit(f):
        return f                                         # same loops in Python: correct, slow


@_jit
def _back_contact_rows(inst, prim, d, ng, first_face, is_contact):
    """:func:`_back_contact_rows_np` in one pass: 5 ns a ray against 43 in numpy where most rays
    hit a contact face from its front (a table top under the camera; measured on the product
    shot's table, 200k rays)."""
    out = np.empty(inst.shape[0], np.int64)
    k = 0
    for r in range(inst.shape[0]):
        i = inst[r]
        if i < 0 or not is_contact[first_face[i] + prim[r]]:
            continue
        if d[r, 0] * ng[r, 0] + d[r, 1] * ng[r, 1] + d[r, 2] * ng[r, 2] > 0.0:
            out[k] = r
            k += 1
    return out[:k]


@_jit
def _face_planes(V, F, M, row, n, w, lo, hi, amax):
    """World planes of the triangles F (f, 3) of vertices V (v, 3) under the affine M (4, 4), into
    rows row.. of n (unit normal; 0 for a degenerate face), w (n . x = w), lo / hi (corner box) and
    amax (largest |coordinate| of a corner)."""
    P = np.empty((3, 3))
    for k in range(F.shape[0]):
        for c in range(3):
            v = V[F[k, c]]
            for a in range(3):
                P[c, a] = M[a, 0] * v[0] + M[a, 1] * v[1] + M[a, 2] * v[2] + M[a, 3]
        e1 = P[1] - P[0]
        e2 = P[2] - P[0]
        nx = e1[1] * e2[2] - e1[2] * e2[1]
        ny = e1[2] * e2[0] - e1[0] * e2[2]
        nz = e1[0] * e2[1] - e1[1] * e2[0]
        L = np.sqrt(nx * nx + ny * ny + nz * nz)
        r = row + k
        if L > 0.0:
            nx, ny, nz = nx / L, ny / L, nz / L
        else:
            nx = ny = nz = 0.0
        n[r, 0], n[r, 1], n[r, 2] = nx, ny, nz
        w[r] = nx * P[0, 0] + ny * P[0, 1] + nz * P[0, 2]
        m = 0.0
        for a in range(3):
            lo[r, a] = min(P[0, a], P[1, a], P[2, a])
            hi[r, a] = max(P[0, a], P[1, a], P[2, a])
            m = max(m, abs(lo[r, a]), abs(hi[r, a]))
        amax[r] = m


@_jit
def _face_keys(n, w, wbin, nbin, key, side):
    """Per face: side = +1 / -1 as its normal points along the canonical orientation (largest
    |component| positive), 0 for a degenerate face; key = one int64 of the rounded canonical normal
    (bins of nbin) and plane offset (bins of wbin)."""
    for r in range(n.shape[0]):
        ax, ay, az = abs(n[r, 0]), abs(n[r, 1]), abs(n[r, 2])
        if ax == 0.0 and ay == 0.0 and az == 0.0:
            side[r] = 0
            key[r] = 0
            continue
        big = n[r, 0] if (ax >= ay and ax >= az) else (n[r, 1] if ay >= az else n[r, 2])
        sg = 1 if big >= 0.0 else -1
        side[r] = sg
        k0 = np.int64(np.round(sg * n[r, 0] / nbin))
        k1 = np.int64(np.round(sg * n[r, 1] / nbin))
        k2 = np.int64(np.round(sg * n[r, 2] / nbin))
        kw = np.int64(np.floor(sg * w[r] / wbin))
        key[r] = ((k0 * 4099 + k1) * 4099 + k2) * 1_000_003 + kw


@_jit
def _join_pairs(pos, kp, neg, kq, inst, n, w, lo, hi, tol, budget, a_out, b_out):
    """Pairs in contact between faces pos (sorted by their keys kp) and neg (sorted, keys kq): for
    each pos face, the neg faces whose key is within one offset bin of its own, tested exactly
    (different instances, normals opposite within COS_OPPOSITE, planes within the larger tol, boxes
    overlapping by tol).  Writes up to a_out.size pairs (a_out None: counts only); returns (pairs
    found, pos faces left out because more than ``budget`` candidates came before them)."""
    found = 0
    seen = 0
    for j in range(pos.shape[0]):
        f = pos[j]
        for shift in (-1, 0, 1):
            q = np.searchsorted(kq, kp[j] + shift)
            while q < kq.shape[0] and kq[q] == kp[j] + shift:
                g = neg[q]
                q += 1
                seen += 1
                if inst[f] == inst[g]:
                    continue
                if n[f, 0] * n[g, 0] + n[f, 1] * n[g, 1] + n[f, 2] * n[g, 2] > -COS_OPPOSITE:
                    continue
                t = max(tol[f], tol[g])
                if abs(w[f] + w[g]) > t:
                    continue
                ok = True
                for c in range(3):
                    if lo[f, c] > hi[g, c] + t or lo[g, c] > hi[f, c] + t:
                        ok = False
                if not ok:
                    continue
                if found < a_out.shape[0]:
                    a_out[found] = f
                    b_out[found] = g
                found += 1
        if seen > budget:
            return found, pos.shape[0] - 1 - j
    return found, 0


def _static_instances(scene) -> list[int]:
    """Indices of the static rigid instances with triangles (the embree static part's)."""
    return [i for i, inst in enumerate(scene.instances)
            if inst.transform.is_static and not scene.meshes[inst.mesh].is_deforming
            and len(scene.meshes[inst.mesh].triangles)]


def _corners(scene, inst: np.ndarray, prim: np.ndarray) -> np.ndarray:
    """(k, 3, 3) world corners of triangle prim[j] of static instance inst[j]."""
    out = np.empty((inst.size, 3, 3))
    for i in np.unique(inst):
        sel = np.flatnonzero(inst == i)
        obj = scene.instances[int(i)]
        mesh = scene.meshes[obj.mesh]
        V = np.asarray(mesh.vertices, np.float64)
        V = V[0] if V.ndim == 3 else V
        M = obj.transform.matrices[0]
        out[sel] = (V[np.asarray(mesh.triangles, np.int64)[prim[sel]]] @ M[:3, :3].T) + M[:3, 3]
    return out


def find_contacts(scene) -> Contacts:
    """The contacts of ``scene`` (:class:`Contacts`): pairs of faces of different static rigid
    instances whose planes coincide within tol with opposite normals and whose boxes overlap.

    Compiled passes over the faces (planes, then keys), a sorted join on the keys with the exact
    test on the candidates (2.2M triangles: 2-4 s on a loaded 2-core machine; docs/raycast.md)."""
    static = _static_instances(scene)
    counts = [len(scene.meshes[scene.instances[i].mesh].triangles) for i in static]
    total = int(sum(counts))
    stride = max([int(c) for c in counts], default=1)
    empty = Contacts(scene, np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(0, np.int32),
                     np.zeros(0, np.int32), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0), stride)
    if len(static) < 2:
        return empty
    # Planes of every static face, instance by instance (no (F, 3, 3) corner array)
    n, w = np.empty((total, 3)), np.empty(total)
    lo, hi, amax = np.empty((total, 3)), np.empty((total, 3)), np.empty(total)
    inst = np.repeat(np.asarray(static, np.int64), counts)
    prim = np.concatenate([np.arange(c, dtype=np.int64) for c in counts])
    row, arrays = 0, {}
    for i, c in zip(static, counts):
        obj = scene.instances[i]
        if obj.mesh not in arrays:                        # copies of one mesh share its arrays
            mesh = scene.meshes[obj.mesh]
            V = np.asarray(mesh.vertices, np.float64)
            arrays[obj.mesh] = (np.ascontiguousarray(V[0] if V.ndim == 3 else V),
                                np.ascontiguousarray(mesh.triangles, np.int64))
        V, F = arrays[obj.mesh]
        _face_planes(V, F, np.ascontiguousarray(obj.transform.matrices[0], np.float64), row, n, w, lo, hi, amax)
        row += c
    off = instance_offsets(scene)
    tol = 2.0 * (off[inst] + OFFSET_POS * amax)
    # Group by rounded canonical normal and plane offset (bins of 2 x the largest tol; the join
    # below also looks one bin either side, so a plane on a bin border still meets its partner)
    wbin = float(tol.max()) * 2.0
    key, side = np.empty(total, np.int64), np.empty(total, np.int64)
    _face_keys(n, w, wbin, _NORMAL_BIN, key, side)
    pos, neg = np.flatnonzero(side > 0), np.flatnonzero(side < 0)
    # Candidate pairs by a sorted join on the keys: each face facing +canonical against the faces
    # facing -canonical in its offset bin and the two next to it (a key collision only adds
    # candidates, which the exact test below rejects)
    order = np.argsort(key[neg], kind="stable")
    neg, kq = neg[order], key[neg][order]
    order = np.argsort(key[pos], kind="stable")          # sorted queries: searchsorted walks in order
    pos, kp = pos[order], key[pos][order]
    none = np.zeros(0, np.int64)
    m, skipped = _join_pairs(pos, kp, neg, kq, inst, n, w, lo, hi, tol, CONTACT_PAIRS_MAX, none, none)
    if m == 0:
        empty.skipped = skipped
        return empty
    a, b = np.empty(m, np.int64), np.empty(m, np.int64)
    _join_pairs(pos, kp, neg, kq, inst, n, w, lo, hi, tol, CONTACT_PAIRS_MAX, a, b)
    # Both directions: a back-face hit on either face finds the other
    src, dst = np.r_[a, b], np.r_[b, a]
    uniq = np.unique(np.stack([src, dst], axis=1), axis=0)
    src, dst = uniq[:, 0], uniq[:, 1]
    key = inst[src] * stride + prim[src]
    order = np.argsort(key, kind="stable")
    key, dst = key[order], dst[order]
    keys, first = np.unique(key, return_index=True)
    start = np.r_[first, key.size].astype(np.int64)
    return Contacts(scene, keys, start, inst[dst].astype(np.int32), prim[dst].astype(np.int32),
                    _corners(scene, inst[dst], prim[dst]), np.ascontiguousarray(n[dst]), w[dst], stride,
                    skipped)


def warm_up() -> float:
    """Compile (or load from numba's cache) this module's kernels on two triangles lying on each
    other; seconds taken (``embree_kernels.warm_up`` calls it)."""
    import time
    from .. import raycast
    from ..scene import Instance, Material, Mesh, Scene
    start = time.perf_counter()
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    up = Mesh(vertices=V, triangles=np.array([[0, 1, 2]], np.int32), material_ids=np.zeros(1, np.int32))
    down = Mesh(vertices=V, triangles=np.array([[0, 2, 1]], np.int32), material_ids=np.zeros(1, np.int32))
    scene = Scene(meshes=[up, down], instances=[Instance(0), Instance(1)], materials=[Material()])
    contacts = find_contacts(scene)
    hits = raycast.Hits.empty(1)
    hits.instance[:], hits.prim[:], hits.t[:] = 1, 0, 1.0
    hits.ng[:], hits.position[:] = (0.0, 0.0, -1.0), (0.2, 0.2, 0.0)
    contacts.resolve(np.array([[0.2, 0.2, 1.0]]), np.array([[0.0, 0.0, -1.0]]), np.zeros(1), np.full(1, np.inf), hits)
    return time.perf_counter() - start
