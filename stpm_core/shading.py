"""What the shader-node interpreter reads for a scene, built once per render.

:func:`shading_data` compiles every material's node graph (:mod:`stpm_core.nodes`) into one
program array, sets each material's ``C_PROGRAM`` column, packs the textures
(:mod:`stpm_core.textures`) and the per-corner mesh attributes the nodes read (UV maps, object-space
corners for Object and Generated coordinates).  Camera paths (``integrator``) and photon paths
(``photons.trace``) pass the same :class:`ShadingData` to ``kernels.svm.shade_closures``.

A scene whose materials have no graph gets empty attribute arrays and every hit reads its
material's constant closure row (the same numbers as before node programs existed).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .colorspaces import luma, working_space_of
from .kernels.closure import C_EMIT, C_PROGRAM, N_CLOSURE, pack_materials
from .kernels.svm import shade
from .kernels.svm_variants import program_ops
from .nodes.compile import compile_graph
from .textures import pack_textures

__all__ = ["ShadingData", "shading_data", "constant_shading", "scene_attributes", "hit_geometry", "normal_matrices", "normal_keys", "frame_keys",
           "surface_emission"]

_I64_0 = np.zeros(0, np.int64)


@dataclass
class ShadingData:
    """closures (M + 1, N_CLOSURE); prog (W,) float64 programs; n_slots; A and X the attribute and
    texture tuples of ``kernels.svm``; uses_programs / uses_mix; unsupported: messages naming
    node inputs the interpreter could not evaluate (they use the socket's default)."""

    closures: np.ndarray
    prog: np.ndarray
    n_slots: int
    A: tuple
    X: tuple
    uses_programs: bool = False
    uses_mix: bool = False
    uses_normals: bool = False        # some program rewrites hits' shading normals (Normal inputs)
    uses_frames: bool = False         # some program reads each hit's normal matrix (Normal Map)
    # the features (opcodes and parts of them, ``kernels.svm_variants.FEATURES``) the programs hold:
    # the interpreter is compiled for these only; None: any (the full interpreter)
    ops: frozenset | None = None
    unsupported: list = field(default_factory=list)
    uv_layers: list = field(default_factory=list)
    texture_bytes: int = 0
    instances: list = field(default_factory=list)     # the scene's instances (normal matrices)
    frame_keys: tuple = None           # (the transforms, normal_keys(instances)), built on first use (frame_keys)
    emitting: frozenset = frozenset()  # materials whose node program may emit (not constant black)
    transparent: frozenset = frozenset()   # materials whose node program may let rays through
    # materials whose program picks its closure per hit (Mix / Add Shader, Alpha) and may pick a
    # scattering one: photons are stored there whatever the pick (``photons.trace``)
    store_any: frozenset = frozenset()

    def _mask(self, which: frozenset) -> np.ndarray:
        """(M + 1,) bool over material ids (index -1: a miss, False) of the set ``which``."""
        mask = np.zeros(self.closures.shape[0], bool)
        mask[list(which)] = True
        return mask

    @cached_property
    def transparent_mask(self) -> np.ndarray:
        """(M + 1,) bool: may hits on material i (index -1: a miss) be transparent?  (Built once.)"""
        return self._mask(self.transparent)

    @cached_property
    def store_mask(self) -> np.ndarray:
        """(M + 1,) bool of ``store_any`` (built once)."""
        return self._mask(self.store_any)


def _empty_attributes(n_inst: int) -> tuple:
    return (np.zeros(max(n_inst, 1), np.int64), np.zeros(1, np.int64), np.full((1, 1), -1, np.int64),
            np.zeros((1, 3, 2), np.float32), np.zeros((1, 3, 3), np.float32), np.zeros((1, 3)), np.ones((1, 3)),
            np.zeros((1, 3, 3), np.float32), np.full((1, 1), -1, np.int64), np.zeros((1, 3, 4), np.float32),
            np.full((1, 1), -1, np.int64), np.zeros((1, 3, 4), np.float32), np.zeros((max(n_inst, 1), 4, 4)),
            np.full(1, -1, np.int64), np.zeros((1, 3, 3), np.float32))


_NM_IDENTITY = np.eye(3)[None].copy()          # (1, 3, 3): every hit's normal matrix is the identity


def constant_shading(closures: np.ndarray) -> ShadingData:
    """Shading without node programs: every hit reads its material's row of ``closures``."""
    return ShadingData(closures=closures, prog=np.zeros(1), n_slots=1, A=_empty_attributes(1),
                       X=pack_textures([]).arrays()[:5])


def scene_attributes(scene, uv_layers: list, color_layers: list | None = None) -> tuple:
    """The attribute tuple A of ``kernels.svm`` for scene's meshes and the UV layer names
    (index 0 of a name list: "" = each mesh's render-active map).

    inst_mesh (I,) int64; mesh_tri0 (M,) int64 first triangle of each mesh in corner_obj;
    uv_off (M, L) int64 first triangle of each (mesh, layer) in corner_uv, -1 = missing;
    corner_uv (N, 3, 2) float32; corner_obj (T, 3, 3) float32 (the shape at the frame's shutter
    time, what Object coordinates read on a mesh that does not deform);
    gen_lo, gen_inv (M, 3): Generated = (p_gen - gen_lo) * gen_inv, the mesh's manual texture
    space (``Mesh.texspace``) or Blender's automatic one (the bounding box of the positions
    Generated reads; an axis of zero extent gets half-size 1, as Blender sets it);
    corner_nrm (T, 3, 3) float32 object-space corner normals (``Mesh.normals``; a deforming mesh's at
    the frame's shutter time, ``Mesh.normals_at``, as Cycles' Normal Map reads the static vertex
    normals and the add-on exports tangents at the frame; flat meshes: the face normal at each
    corner); tan_off (M, L) int64 and corner_tan (N', 3, 4) float32 the
    per-corner tangents and signs of each (mesh, layer) (``Mesh.tangents``), -1 = none;
    col_off (M, Lc) int64 and corner_col (N'', 3, 4) float32 the per-corner RGBA of each colour
    layer name of ``color_layers`` ("" = the mesh's render-active colour attribute): the mesh's
    colour attribute of that name (``Mesh.color_layers``), else its UV map of that name as
    (u, v, 0, 1) (an Attribute node may name either), else -1 (none: the node reads 0);
    inst_obj (I, 4, 4) float64: for an instance of a deforming mesh the world -> object matrix at
    the frame (row 3 = 0 0 0 1), whose Object coordinates are that matrix times the hit point;
    zero elsewhere (Object = corner_obj at the hit's barycentrics); gen_tri0 (M,) int64 first
    triangle of each mesh in corner_gen (T', 3, 3) float32, its undeformed corners (``Mesh.orco``)
    that Generated reads, -1 = none (Generated reads corner_obj).
    """
    meshes = scene.meshes
    M = len(meshes)
    L = max(len(uv_layers), 1)
    sh = getattr(scene, "shutter", None)
    span = float(sh.close - sh.open) if sh is not None else 0.0
    u_frame = float(np.clip((float(getattr(scene, "frame", 0.0)) - sh.open) / span, 0.0, 1.0)) if span > 0 else 0.5
    inst_mesh = np.array([inst.mesh for inst in scene.instances] or [0], np.int64)
    mesh_tri0 = np.zeros(max(M, 1), np.int64)
    uv_off = np.full((max(M, 1), L), -1, np.int64)
    gen_lo, gen_inv = np.zeros((max(M, 1), 3)), np.ones((max(M, 1), 3))
    objs, uvs, nrms, tans, gens = [], [], [], [], []
    gen_tri0 = np.full(max(M, 1), -1, np.int64)
    n_gen = 0
    tan_off = np.full((max(M, 1), L), -1, np.int64)
    n_tri = n_uv = n_tan = 0
    for i, m in enumerate(meshes):
        # Object reads the shape at the frame (a deforming mesh's hits use inst_obj instead)
        V = np.asarray(m.vertices_at(u_frame), np.float32)
        F = np.asarray(m.triangles, np.int64)
        mesh_tri0[i] = n_tri
        corners = V[F] if F.size else np.zeros((0, 3, 3), np.float32)
        objs.append(corners)
        # Generated reads the undeformed positions (Mesh.orco; none given: the same shape)
        orco = getattr(m, "orco", None)
        if orco is not None and F.size:
            orco = np.asarray(orco, np.float32)
            gen_tri0[i] = n_gen
            gens.append(orco[F])
            n_gen += F.shape[0]
            V = orco
        if m.normals is not None:
            # a deforming mesh: its normals at the frame (Cycles reads its static vertex normals)
            nrms.append(np.asarray(m.normals_at(u_frame), np.float32).reshape(F.shape[0], 3, 3))
        else:
            fn = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]).astype(np.float64)
            fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
            nrms.append(np.repeat(fn[:, None, :], 3, axis=1).astype(np.float32))
        n_tri += F.shape[0]
        ts = getattr(m, "texspace", None)
        if ts is not None:
            # a manual texture space (Mesh.texspace: location, size)
            loc, size = np.asarray(ts, np.float64)[0], np.asarray(ts, np.float64)[1]
            size = np.where(size == 0.0, 1.0, size)
            gen_lo[i], gen_inv[i] = loc - size, 1.0 / (2.0 * size)
        elif V.shape[0]:
            lo, hi = V.min(axis=0).astype(np.float64), V.max(axis=0).astype(np.float64)
            loc, size = 0.5 * (lo + hi), 0.5 * (hi - lo)
            size = np.where(size == 0.0, 1.0, np.where(size < 1e-5, 1e-5, size))
            gen_lo[i], gen_inv[i] = loc - size, 1.0 / (2.0 * size)
        layers = getattr(m, "uv_layers", None) or {}
        for j, name in enumerate(uv_layers):
            key = name if name else (m.uv_render if m.uv_render in layers else next(iter(layers), None))
            uv = layers.get(key) if key is not None else None
            if uv is None:
                continue
            uv = np.asarray(uv, np.float32).reshape(F.shape[0], 3, 2)
            uv_off[i, j] = n_uv
            uvs.append(uv)
            n_uv += uv.shape[0]
            tan = (getattr(m, "tangents", None) or {}).get(key)
            if tan is not None:
                tan_off[i, j] = n_tan
                tans.append(np.asarray(tan, np.float32).reshape(F.shape[0], 3, 4))
                n_tan += F.shape[0]
    corner_obj = np.concatenate(objs).astype(np.float32) if n_tri else np.zeros((1, 3, 3), np.float32)
    corner_uv = np.concatenate(uvs).astype(np.float32) if n_uv else np.zeros((1, 3, 2), np.float32)
    corner_nrm = np.concatenate(nrms).astype(np.float32) if n_tri else np.zeros((1, 3, 3), np.float32)
    corner_tan = np.concatenate(tans).astype(np.float32) if n_tan else np.zeros((1, 3, 4), np.float32)
    col_off, corner_col = _color_attributes(meshes, list(color_layers or []))
    # Object coordinates of a deforming mesh: the hit's own position taken to object space (Cycles:
    # the inverse object transform of P at the ray's time), so the texture stays put in object
    # space while the surface deforms through it; the transform at the frame (exact unless the
    # object also moves rigidly).  Other meshes read corner_obj, exact at every time.
    inst_obj = np.zeros((max(len(scene.instances), 1), 4, 4))
    for k, inst in enumerate(scene.instances):
        if meshes[inst.mesh].is_deforming:
            M = np.asarray(inst.transform.at(u_frame), np.float64)
            if abs(np.linalg.det(M[:3, :3])) > 1e-300:       # (a zero scale: corner_obj, as other meshes)
                inst_obj[k] = np.linalg.inv(M)
                inst_obj[k, 3] = (0.0, 0.0, 0.0, 1.0)
    return (inst_mesh, mesh_tri0, uv_off, np.ascontiguousarray(corner_uv), np.ascontiguousarray(corner_obj),
            gen_lo, gen_inv, np.ascontiguousarray(corner_nrm), tan_off, np.ascontiguousarray(corner_tan),
            col_off, corner_col, inst_obj, gen_tri0,
            np.ascontiguousarray(np.concatenate(gens) if n_gen else np.zeros((1, 3, 3), np.float32), np.float32))


def _color_attributes(meshes, names: list) -> tuple:
    """(col_off (M, Lc) int64, corner_col (N, 3, 4) float32) of :func:`scene_attributes`."""
    M = max(len(meshes), 1)
    col_off = np.full((M, max(len(names), 1)), -1, np.int64)
    parts, n = [], 0
    for i, m in enumerate(meshes):
        F = int(np.asarray(m.triangles).shape[0])
        colors = getattr(m, "color_layers", None) or {}
        uvs = getattr(m, "uv_layers", None) or {}
        for j, name in enumerate(names):
            key = name if name else getattr(m, "color_render", None)
            if key in colors:
                a = np.asarray(colors[key], np.float32).reshape(F, 3, 4)
            elif name and name in uvs:
                a = np.zeros((F, 3, 4), np.float32)
                a[:, :, :2] = np.asarray(uvs[name], np.float32).reshape(F, 3, 2)
                a[:, :, 3] = 1.0
            else:
                continue
            col_off[i, j] = n
            parts.append(a)
            n += F
    corner_col = np.concatenate(parts) if n else np.zeros((1, 3, 4), np.float32)
    return col_off, np.ascontiguousarray(corner_col, np.float32)


def shading_data(scene, closures: np.ndarray | None = None) -> ShadingData:
    """Build (or reuse: cached on the scene while its materials, meshes and textures lists are
    the same objects with the same lengths) the scene's :class:`ShadingData`."""
    working = working_space_of(getattr(scene, "metadata", None))
    key = (id(scene.materials), len(scene.materials), id(scene.meshes), len(scene.meshes),
           id(getattr(scene, "textures", [])), len(getattr(scene, "textures", [])), len(scene.instances),
           tuple(id(m.graph) for m in scene.materials), working)
    cached = scene.__dict__.get("_shading_data")
    base = pack_materials(scene.materials) if closures is None else closures
    if cached is not None and cached[0] == key and (cached[2] is base or np.array_equal(cached[2], base)):
        return cached[1]
    rows = base.copy()
    textures = list(getattr(scene, "textures", []) or [])
    uv_layers: list = [""]
    color_layers: list = []
    words, unsupported, uses_mix, uses_normals, uses_frames = [], [], False, False, False
    ops: set = set()
    emitting, transparent, store_any = set(), set(), set()
    at = 0
    for i, m in enumerate(scene.materials):
        g = getattr(m, "graph", None)
        if g is None:
            continue
        prog = compile_graph(g, n_textures=len(textures), uv_layers=uv_layers, color_layers=color_layers,
                             luma=luma(working))
        w = prog.words                 # jumps are relative to the program's start: no relocation
        words.append(w)
        rows[i, C_PROGRAM] = float(at)
        at += w.size
        uses_mix |= prog.uses_mix
        uses_normals |= prog.uses_normals
        uses_frames |= prog.uses_frames
        if prog.may_emit:
            emitting.add(i)
        if prog.may_pass:
            transparent.add(i)
        if prog.uses_mix and prog.may_scatter:
            store_any.add(i)
        unsupported += [f"material {m.name!r}: {u}" for u in prog.unsupported]
    prog_all = np.concatenate(words) if words else np.zeros(1)
    starts = [int(r) for r in rows[:-1, C_PROGRAM] if r >= 0]
    n_slots = max([int(prog_all[s]) for s in starts] + [1])
    if words:
        A = scene_attributes(scene, uv_layers, color_layers)
        pack = pack_textures(textures, working)
        hdr = pack.arrays()[0]
        for w in words:
            ops |= program_ops(w, hdr)
    else:
        A = _empty_attributes(len(scene.instances))
        pack = pack_textures([])
    sd = ShadingData(closures=rows, prog=prog_all, n_slots=n_slots, A=A, X=pack.arrays()[:5],
                     uses_programs=bool(words), uses_mix=uses_mix, uses_normals=uses_normals, uses_frames=uses_frames,
                     ops=frozenset(ops),
                     unsupported=unsupported, uv_layers=uv_layers,
                     texture_bytes=pack.nbytes if words else 0, instances=list(scene.instances),
                     emitting=frozenset(emitting), transparent=frozenset(transparent),
                     store_any=frozenset(store_any))
    scene.__dict__["_shading_data"] = (key, sd, base)
    return sd


def normal_matrices(instances, inst: np.ndarray, times: np.ndarray, keys: tuple | None = None) -> np.ndarray:
    """(m, 3, 3) object-to-world normal matrices (inverse transpose of each instance's linear part)
    of hits on ``instances[inst]`` (inst (m,)) at normalised times (m,).

    keys: :func:`normal_keys` of ``instances`` (a caller shading many batches keeps them; None:
    built here).  One pass of ``kernels.motion.normal_matrix_rows``: a static instance's matrix
    copied, a moving one's evaluated at the hit's time."""
    from .kernels.motion import normal_matrix_rows
    if keys is None:
        keys = normal_keys(instances)
    out = np.empty((inst.shape[0], 3, 3))
    normal_matrix_rows(np.ascontiguousarray(inst, np.int32), np.ascontiguousarray(times, np.float64), *keys, out)
    return out


def frame_keys(sd: ShadingData) -> tuple:
    """:func:`normal_keys` of ``sd.instances``, kept in ``sd.frame_keys`` while every instance keeps
    the same transform object (the shading data outlives a render; a transform replaced between
    renders is seen)."""
    trs = [ins.transform for ins in sd.instances]
    kept = sd.frame_keys                 # (the transforms themselves: compared by identity, kept alive)
    if kept is None or len(kept[0]) != len(trs) or any(a is not b for a, b in zip(kept[0], trs)):
        kept = sd.frame_keys = (trs, normal_keys(sd.instances))
    return kept[1]


def _normal_matrix(A: np.ndarray) -> np.ndarray:
    """(3, 3) what object-space normals are multiplied by under the linear part ``A`` (3, 3) of an
    instance's transform: ``inv(A).T``; for a singular ``A`` (an object scaled to 0 along an axis,
    or to 0 altogether: a "pop-in" keyframe) the cofactor matrix, ``det(A) inv(A).T``'s limit, whose
    columns are a1 x a2, a2 x a0, a0 x a1 (a flattened object keeps its flat side's normal), or the
    identity when that is 0 too (no triangle of such an instance has an area to be hit).  Before,
    ``np.linalg.inv`` raised and the render stopped ("LinAlgError: Singular matrix": artist review 4)."""
    if abs(np.linalg.det(A)) > 1e-300:
        return np.linalg.inv(A).T
    a0, a1, a2 = A[:, 0], A[:, 1], A[:, 2]
    C = np.column_stack([np.cross(a1, a2), np.cross(a2, a0), np.cross(a0, a1)])
    return C if np.abs(C).max() > 0 else np.eye(3)


def normal_keys(instances) -> tuple:
    """What ``kernels.motion.normal_matrix_rows`` reads of ``instances``: (NM0 (n, 3, 3) each static
    instance's ``np.linalg.inv(M[:3, :3]).T``, moving (n,) int64 the moving instance's transform
    index or -1, then the stacked keys of the moving ones: knots (K,), T (K, 3), Q (K, 4),
    S (K, 3, 3), first (J,), last (J,) int64)."""
    n = len(instances)
    NM0 = np.zeros((max(n, 1), 3, 3))
    moving = np.full(max(n, 1), -1, np.int64)
    knots, T, Q, S, first, last = [np.zeros(0)], [np.zeros((0, 3))], [np.zeros((0, 4))], [np.zeros((0, 3, 3))], [], []
    at = 0
    for i, ins in enumerate(instances):
        tr = ins.transform
        if tr.is_static:
            NM0[i] = _normal_matrix(np.asarray(tr.matrices[0], np.float64)[:3, :3])
            continue
        moving[i] = len(first)
        K = tr.times.shape[0]
        knots.append(tr.times), T.append(tr._T), Q.append(tr._Q), S.append(tr._S)
        first.append(at), last.append(at + K - 1)
        at += K
    c = np.ascontiguousarray
    return (c(NM0), moving, c(np.concatenate(knots), np.float64), c(np.concatenate(T), np.float64),
            c(np.concatenate(Q), np.float64), c(np.concatenate(S), np.float64),
            np.asarray(first, np.int64), np.asarray(last, np.int64))


def hit_geometry(hits, d: np.ndarray, rows: np.ndarray | None = None, *, sd=None, times=None) -> tuple:
    """The per-hit tuple G of ``kernels.svm`` from a ``raycast.Hits`` and its rays d (m, 3)
    (rows: a subset of the hits, in that order; d and times are then already that subset's).
    sd: the scene's :class:`ShadingData`; when its programs read normal matrices (``uses_frames``)
    each hit's is computed at its time (times (m,)), else G holds the (1, 3, 3) identity.
    With rows, NS is a copy: write it back (``hits.ns[rows] = G[2]``) when programs set normals."""
    if rows is None:
        G = (hits.position, hits.ng, hits.ns, np.ascontiguousarray(d, np.float64), hits.instance, hits.prim,
             hits.u, hits.v)
    else:
        G = (hits.position[rows], hits.ng[rows], hits.ns[rows], np.ascontiguousarray(d, np.float64),
             hits.instance[rows], hits.prim[rows], hits.u[rows], hits.v[rows])
    frames = sd is not None and sd.uses_frames
    NM = normal_matrices(sd.instances, G[4], times, frame_keys(sd)) if frames else _NM_IDENTITY
    return G + (NM,)


def surface_emission(sd: ShadingData, mat: np.ndarray, inst: np.ndarray, prim: np.ndarray, bu: np.ndarray,
                     bv: np.ndarray, P: np.ndarray, N: np.ndarray, D: np.ndarray, times: np.ndarray,
                     seed: int = 0) -> np.ndarray:
    """Emitted radiance (n, 3) W m^-2 sr^-1 of n surface points, as a camera ray would see them.

    mat, inst, prim (n,) int32: material, instance, triangle (within its mesh); bu, bv (n,)
    barycentrics (the ray caster's u, v); P (n, 3) world positions; N (n, 3) the normal the nodes
    read (as geometric and shading normal); D (n, 3) unit directions of the rays arriving there;
    times (n,) normalised shutter times (normal matrices); seed: Mix Shader choices
    (``kernels.svm.hash_uniform(seed, row)``, as on camera paths).  The node programs run exactly
    as at a camera hit (``kernels.svm.shade``): what a textured emitter emits is what it shows.
    """
    n = mat.shape[0]
    C = np.empty((n, N_CLOSURE))
    f8 = lambda a: np.ascontiguousarray(a, np.float64)   # noqa: E731
    i4 = lambda a: np.ascontiguousarray(a, np.int32)     # noqa: E731
    inst = i4(inst)
    NM = normal_matrices(sd.instances, inst, times, frame_keys(sd)) if sd.uses_frames else _NM_IDENTITY
    G = (f8(P), f8(N), f8(N).copy(), f8(D), inst, i4(prim), f8(bu), f8(bv), NM)
    shade(sd, i4(mat), G if sd.uses_programs else None, int(seed), C)
    return C[:, C_EMIT:C_EMIT + 3].copy()
