"""The effects plan: which effects a scene calls for, and why (``stpm plan``).

``make_plan(scene, settings) -> dict`` decides, from the exported scene alone,
what the renderer must simulate; :func:`apply_plan` turns it into the settings
the renderer acts on, so what ``stpm plan`` prints is what ``stpm render`` does.
The rules (docs/effects.md has them with what each one saves):

* **motion_blur** -- the shutter is open (length > 0 frames) and something
  moves within it: an object (rigid motion), a deforming mesh, the camera or
  an emitting light.
* **caustics** -- light can reach a specular surface and from there a diffuse
  one (paths L S+ D): an instance with a delta lobe (clear glass, a smooth
  mirror, a smooth coat) exists, a light with power > 0 reaches it (spot cone,
  area-light side, and a small photon probe through the scene: 512 photons
  aimed at each specular object), and a diffuse surface exists to receive the
  focused light -- unless the probe's caustic is faint: its brightest irradiance under
  ``CAUSTIC_CONTRAST_MIN`` of the mean direct irradiance on lit diffuse surfaces and its flux
  under ``CAUSTIC_POWER_MIN`` of the direct flux (:func:`caustic_contrast`).
* **indirect** -- diffuse interreflection worth a global map (paths L D+ D):
  light reaches a diffuse surface (a probe of 2048 photons per light over its
  whole emission) and that light can bounce onto a diffuse surface again: at
  least two diffuse objects, or one diffuse mesh that can see itself
  (non-convex: a room, a bowl; a plane or a convex solid cannot), or specular
  surfaces that send a lone diffuse object's light back onto it (L D S+ D: a
  floor under a glass or water plane): the probe's photons traced on as the
  global map's return at least ``PROBE_RETURN_MIN`` of the emitted power.
* **time_dependent** -- photon-mapped light must carry time: something other
  than the camera moves (objects, deformation, lights) while the shutter is
  open, and a photon map is built.  A camera pan over a static scene is motion
  blur but not time dependent: the lighting is the same at every instant, so
  the STANDARD estimate is exact.

``settings.effects == 'MANUAL'`` replaces the caustics / indirect decisions by
``settings.caustics`` / ``settings.indirect``; motion is always read from the
scene.  ``settings.diffuse_bounces == 0`` turns both off whatever the rest says (Cycles'
direct light only: every photon-map look-up is a diffuse bounce of the camera path).  The
renderer follows the plan (:func:`apply_plan`): 0 caustic photons
without caustics, 0 global photons without indirect light, and the STANDARD
estimator when the plan is not time dependent (static photon maps need no
temporal selection; every estimator then converges to the same answer and
STANDARD does it with the fewest look-up candidates).
"""
from __future__ import annotations

import json

import numpy as np

from .shading import shading_data
from .bsdf import MaterialTable
from .nodes.graph import shader_lobes
from .photons.trace import trace_photon_paths
from .raycast.geometry import instance_offsets
from .sampling import rng_for, stratified_1d

__all__ = ["make_plan", "apply_plan", "format_plan", "plan_summary", "EFFECT_KEYS",
           "PROBE_PHOTONS_AIMED", "PROBE_PHOTONS_LIGHT", "CAUSTIC_CONTRAST_MIN", "CAUSTIC_POWER_MIN",
           "caustic_contrast"]

EFFECT_KEYS = ("motion_blur", "caustics", "indirect", "time_dependent")
PROBE_PHOTONS_AIMED = 512    # probe photons per (light, specular object) pair
PROBE_PHOTONS_AIMED_RETRY = 4096   # second round when the first stored no caustic photon
PROBE_PHOTONS_LIGHT = 2048   # probe photons per light over its whole emission
PROBE_RETURN_DEPTH = 4       # bounces the probe follows for light sent back by specular surfaces
PROBE_RETURN_MIN = 0.005     # returned power (global-map photons' over emitted) that calls for indirect light
#: the caustic map is left out when the probe's brightest caustic irradiance is below CAUSTIC_CONTRAST_MIN of
#: the mean direct irradiance on the lit diffuse surfaces AND its flux below CAUSTIC_POWER_MIN of the direct
#: flux landing on them (docs/effects.md, "A caustic too faint to map"): dim and carrying little light
CAUSTIC_CONTRAST_MIN = 0.01
CAUSTIC_POWER_MIN = 0.001
CAUSTIC_CONTRAST_K = 8       # probe caustic photons per density estimate (the brightest one counts)
STREAM_PLAN = 0x91A7         # rng stream of the probe (independent of the render's streams)
_MAX_CONVEXITY_WORK = 4_000_000   # faces x vertices examined by the self-visibility test
_MESH_FACTS_MAX = 4096             # per-mesh answers remembered across plans (LRU-less: cleared when full)
_MESH_FACTS: dict = {}


def mesh_fact(fn, mesh):
    """fn(mesh), remembered by the mesh's content (``Mesh.content_digest``).

    Scenes often hold many copies of one mesh (duplicated objects each get
    their own Mesh), and an animation plans every frame: the watertightness and
    self-visibility tests (about 5 and 25 ms for a 2k-triangle mesh) then run
    once per distinct mesh, not once per object and frame.
    """
    key = (fn.__name__, mesh.content_digest())
    if key not in _MESH_FACTS:
        if len(_MESH_FACTS) >= _MESH_FACTS_MAX:
            _MESH_FACTS.clear()
        _MESH_FACTS[key] = fn(mesh)
    return _MESH_FACTS[key]


# ----------------------------------------------------------------------------
# Material and mesh classification
# ----------------------------------------------------------------------------
def _material_kinds(scene) -> tuple[np.ndarray, np.ndarray]:
    """(M,) bool arrays: material has a delta lobe / reflects diffusely.

    Delta and glossy lobes are the ones the caustic tracer follows (``photons.trace.has_delta``):
    any glass, any metal (smooth: a mirror; rough: glossy caustics), a smooth coat over a base.
    Diffuse = a Lambertian base with a non-black colour (where photon
    irradiance becomes radiance).

    A material with a node graph also counts each lobe some hit can pick
    (:func:`stpm_core.nodes.shader_lobes`): its constants are the blend of a Mix Shader's
    branches, whose roughness hides a smooth coat and whose textured Fac (socket value 0 or 1)
    hides a whole branch.
    """
    delta, diffuse = [], []
    for m in scene.materials:
        w_metal = float(m.metallic)
        w_glass = (1.0 - w_metal) * float(m.transmission)
        w_base = (1.0 - w_metal) * (1.0 - float(m.transmission))
        smooth = float(m.roughness) == 0.0
        g_caustic, g_diffuse = shader_lobes(m.graph) if getattr(m, "graph", None) is not None else (False, False)
        delta.append(w_glass > 0 or w_metal > 0 or (smooth and w_base > 0 and m.specular > 0) or g_caustic)
        diffuse.append((w_base > 0 and bool(np.any(np.asarray(m.base_color, float) > 0))) or g_diffuse)
    return np.array(delta, bool), np.array(diffuse, bool)


def _mesh_materials(mesh) -> np.ndarray:
    """Material indices used by a mesh's triangles, (m,) int."""
    mid = np.asarray(mesh.material_ids)
    return np.unique(mid) if mid.size else np.empty(0, int)


def _mesh_is_closed(mesh) -> bool:
    """Every edge shared by exactly two triangles (a watertight surface), after welding equal vertices."""
    V = np.asarray(mesh.vertices, float)
    V = V[0] if V.ndim == 3 else V
    tri = np.asarray(mesh.triangles)
    if tri.shape[0] == 0:
        return False
    # Weld coincident vertices (UV-sphere poles and seams are split in many exporters)
    _, weld = np.unique(np.round(V, 9), axis=0, return_inverse=True)
    tri = weld.reshape(-1)[tri]
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0])]
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool(counts.size) and bool(np.all(counts == 2))


def self_reflecting(mesh) -> bool:
    """Can light leaving one face of this mesh land on another face of it?

    A face sees the part of space in front of it (its normal side) and, for an
    open surface, behind it too (a surface is two-sided).  The mesh can light
    itself when some vertex lies strictly in front of some face plane (a room
    seen from inside, a concave solid) or, for an open surface, off some face
    plane at all (a bowl, a folded sheet).  A plane or a convex closed solid
    cannot.  Faces are subsampled beyond ~4 M face x vertex pairs.
    """
    V = np.asarray(mesh.vertices, float)
    V = V[0] if V.ndim == 3 else V
    tri = np.asarray(mesh.triangles)
    if tri.shape[0] < 2 or V.shape[0] < 4:
        return False
    # Face planes (unit normals from the winding), zero-area faces dropped
    a, b, c = V[tri[:, 0]], V[tri[:, 1]], V[tri[:, 2]]
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1)
    ok = ln > 1e-12 * max(float(np.ptp(V, axis=0).max()), 1e-30) ** 2
    a, n = a[ok], n[ok] / ln[ok, None]
    if a.shape[0] == 0:
        return False
    closed = _mesh_is_closed(mesh)
    tol = 1e-6 * max(float(np.linalg.norm(np.ptp(V, axis=0))), 1e-30)
    # Deterministic face subsample when the full test would be too big
    step = max(1, int(np.ceil(a.shape[0] * V.shape[0] / _MAX_CONVEXITY_WORK)))
    a, n = a[::step], n[::step]
    for i0 in range(0, a.shape[0], 256):
        s = np.einsum("fk,vk->fv", n[i0:i0 + 256], V) - np.sum(n[i0:i0 + 256] * a[i0:i0 + 256], axis=1)[:, None]
        if np.any(s > tol) or (not closed and np.any(s < -tol)):
            return True
    return False


# ----------------------------------------------------------------------------
# Geometric reach tests (no ray casting)
# ----------------------------------------------------------------------------
def _bounding_sphere(scene, inst) -> tuple[np.ndarray, float] | None:
    """World bounding sphere (centre (3,), radius) of an instance over the shutter."""
    vlo, vhi = scene.meshes[inst.mesh].vertex_bounds()
    if not np.all(np.isfinite(vlo)):
        return None                                   # no vertices
    lo, hi = inst.transform.bounds_of(vlo, vhi)
    return 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-12)


def _light_faces(light, c: np.ndarray, r: float) -> bool:
    """Can the light emit toward the sphere (c, r) at some sampled time?  (spot cone, area side)."""
    if light.type in ("POINT", "SUN", "WORLD", "MESH"):       # an emissive mesh emits from both sides
        return True
    M = light.transform.at(np.linspace(0.0, 1.0, 1 if light.transform.is_static else 9))
    pos, axis = M[:, :3, 3], -M[:, :3, 2]
    axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
    to_c = c[None, :] - pos
    d = np.linalg.norm(to_c, axis=1)
    if light.type == "AREA":
        # One-sided emitter: some point of the sphere in front of the plane (light size included)
        return bool(np.any(np.sum(to_c * axis, axis=1) > -(r + float(light.size) + float(light.size_y))))
    # SPOT: angle to the sphere centre minus its angular radius inside the half cone
    inside = d <= r + float(light.radius)
    cos_c = np.sum(to_c * axis, axis=1) / np.maximum(d, 1e-300)
    ang = np.arccos(np.clip(cos_c, -1.0, 1.0)) - np.arcsin(np.clip((r + float(light.radius)) / np.maximum(d, 1e-300), 0, 1))
    return bool(np.any(inside | (ang <= 0.5 * float(light.spot_size))))


def world_light(scene):
    """The world as a light entry (:class:`~stpm_core.world_light.WorldLight`) around the scene's sphere."""
    from .world_light import WorldLight
    return WorldLight(scene.world.radiance, *scene.bounding_sphere(), world=scene.world)


def _lightset_index(lights, n_scene: int) -> list[int]:
    """Plan light index -> LightSet index: the first ``n_scene`` (the scene's lights, then the emissive
    meshes, in LightSet's order) keep theirs; the world is LightSet's WORLD entry."""
    idx = list(range(n_scene))
    idx += [i for i, l in enumerate(lights.lights) if l.type == "WORLD"]
    return idx


# ----------------------------------------------------------------------------
# Photon probe (a few thousand rays through the real caster)
# ----------------------------------------------------------------------------
def _probe(scene, settings, caster, lights, spec_targets: dict, emitting: list[int], diffuse_inst: set,
           closed_inst: set, ls_index=None) -> dict:
    """First hits of probe photons: which specular / diffuse instances light reaches.

    A hit on the inside (back face) of a closed mesh is light shut in that
    object: it cannot bounce out onto anything else, so it does not count as lit.

    ``emitting`` are plan light indices (the scene's lights, then the world); ``ls_index`` maps
    them to ``lights`` (LightSet) indices (None: the same).

    Returns {'reach_specular': {li: set(instance)}, 'lit_diffuse': set(instance),
    'caustic_stored': int, 'aimed': int, 'emitted': int}.
    """
    ls_index = ls_index if ls_index is not None else list(range(len(lights)))
    seed = int(getattr(settings, "seed", 0)) if settings is not None else 0
    max_depth = int(getattr(settings, "max_depth", 8)) if settings is not None else 8
    table = MaterialTable(scene.materials)
    inst_offset = instance_offsets(scene)
    out = {"reach_specular": {}, "lit_diffuse": set(), "caustic_stored": 0, "aimed": 0, "emitted": 0,
           "return_power": 0.0, "emitted_power": 0.0, "caustic_records": [], "direct_diffuse_power": 0.0}
    # -- Aimed photons: does each light reach each specular object, and a diffuse one after it?
    #    A second, larger round only when the first one found no caustic path at all.
    for rnd, n in enumerate((PROBE_PHOTONS_AIMED, PROBE_PHOTONS_AIMED_RETRY)):
        if rnd == 1 and (out["caustic_stored"] > 0 or not out["reach_specular"]):
            break
        _aimed_round(out, scene, caster, table, lights, spec_targets, emitting, n, seed, rnd, max_depth, inst_offset,
                     ls_index)
    # -- Photons over each light's whole emission: which diffuse objects are lit directly
    for li in emitting:
        n = PROBE_PHOTONS_LIGHT
        rng = rng_for(seed, STREAM_PLAN, 2, li)
        t = scene.shutter.sample(stratified_1d(n, rng))
        o, d, Phi = lights.emit(ls_index[li], n, t, rng)
        live = np.any(Phi > 0, axis=1)
        if not np.any(live):
            continue
        hits = caster.intersect(o[live], d[live], t[live], None)
        out["emitted"] += int(live.sum())
        inst = hits.instance[hits.hit]
        inside = np.sum(d[live][hits.hit] * hits.ng[hits.hit], axis=1) > 0.0
        shut = np.isin(inst, np.fromiter(closed_inst, int, len(closed_inst))) & inside
        if spec_targets:
            # light a specular surface sends back onto diffuse geometry after a diffuse bounce
            # (L D S+ D: a floor under a glass or water plane): the global map's photons, of the
            # paths not shut inside a closed object at their first hit
            go = np.ones(int(live.sum()), bool)
            go[np.flatnonzero(hits.hit)[shut]] = False
            idx = np.flatnonzero(live)[go]
            recs = trace_photon_paths(caster, table, o[idx], d[idx], Phi[idx], t[idx], rng, mode="global",
                                      max_depth=min(max_depth, PROBE_RETURN_DEPTH), inst_offset=inst_offset,
                                      shading=shading_data(scene, table.closures))
            out["return_power"] += float(np.sum(recs["power"], dtype=np.float64))
            out["emitted_power"] += float(np.sum(Phi[live], dtype=np.float64))
        lit_now = ~shut & np.isin(inst, np.fromiter(diffuse_inst, int, len(diffuse_inst)))
        out["direct_diffuse_power"] += float(np.sum(Phi[live][hits.hit][lit_now], dtype=np.float64))
        out["lit_diffuse"].update(int(i) for i in np.unique(inst[~shut]) if int(i) in diffuse_inst)
    return out


def _aimed_round(out, scene, caster, table, lights, spec_targets, emitting, n, seed, rnd, max_depth, inst_offset,
                 ls_index) -> None:
    """n photons per (light, specular object) pair: first hits on the object, caustic photons stored."""
    for li in emitting:
        for pi, (ii, (c, r)) in enumerate(spec_targets.items()):
            rng = rng_for(seed, STREAM_PLAN, 1, rnd, li, pi)
            t = scene.shutter.sample(stratified_1d(n, rng))
            o, d, Phi = lights.emit_toward(ls_index[li], n, t, rng, c, r)
            live = np.any(Phi > 0, axis=1)
            if not np.any(live):
                continue
            hits = caster.intersect(o[live], d[live], t[live], None)
            out["aimed"] += int(live.sum())
            if np.any(hits.instance == ii):
                out["reach_specular"].setdefault(li, set()).add(ii)
                recs = trace_photon_paths(caster, table, o[live], d[live], Phi[live], t[live], rng, mode="caustic",
                                          max_depth=max_depth, inst_offset=inst_offset, target_instance=ii,
                                          shading=shading_data(scene, table.closures))
                out["caustic_stored"] += int(recs.shape[0])
                out["caustic_records"].append(recs)


def _world_area(scene, i: int) -> float:
    """Surface area (one side, m^2) of instance i in world space, at mid-shutter."""
    inst = scene.instances[i]
    mesh = scene.meshes[inst.mesh]
    V = np.asarray(mesh.vertices, float)
    V = V[V.shape[0] // 2] if V.ndim == 3 else V
    tri = np.asarray(mesh.triangles)
    if tri.shape[0] == 0 or V.shape[0] == 0:
        return 0.0
    M = inst.transform.at(0.5)
    W = V @ M[:3, :3].T + M[:3, 3]
    a, b, c = W[tri[:, 0]], W[tri[:, 1]], W[tri[:, 2]]
    return 0.5 * float(np.sum(np.linalg.norm(np.cross(b - a, c - a), axis=1)))


def caustic_contrast(records: list, direct_power: float, lit_area: float, k: int = CAUSTIC_CONTRAST_K) -> float:
    """How bright the probe's caustic gets against the direct light: the brightest caustic irradiance
    (mean RGB, W/m^2) of the probe's stored caustic photons, each a k-nearest density estimate over
    them (its k nearest, itself included: sum of power / (pi r_k^2)), over the mean direct irradiance on
    the lit diffuse surfaces (the probe's direct power landing on them / their one-sided area).

    The probe photons aimed at each (light, specular object) pair carry that pair's flux (``emit_toward``),
    so together they sample the caustic flux of every pair; the maximum over noisy k = 8 estimates reads
    high, which errs toward keeping a caustic.  inf when it cannot tell (fewer than 2 photons stored, no
    direct light or area, coincident photons)."""
    recs = [r for r in records if r.shape[0]]
    if not recs or direct_power <= 0.0 or lit_area <= 0.0:
        return float("inf")
    r = np.concatenate(recs)
    if r.shape[0] < 2:
        return float("inf")
    from scipy.spatial import cKDTree
    pos = np.asarray(r["position"], np.float64)
    pw = np.asarray(r["power"], np.float64).mean(axis=1)
    kk = min(int(k), r.shape[0])
    dist, idx = cKDTree(pos).query(pos, k=kk)
    rk = dist[:, -1]
    if np.any(rk <= 0.0):
        return float("inf")
    e_caustic = np.sum(pw[idx], axis=1) / (np.pi * rk * rk)
    e_direct = direct_power / 3.0 / lit_area                # mean RGB, as the caustic's
    return float(e_caustic.max() / e_direct)


# ----------------------------------------------------------------------------
# The plan
# ----------------------------------------------------------------------------
def _names(items) -> list[str]:
    return [str(x) for x in items]


def make_plan(scene, settings=None, *, caster=None, lights=None, probe: bool = True) -> dict:
    """The effects plan for ``scene`` (rules in the module docstring).

    Parameters
    ----------
    scene : a validated :class:`~stpm_core.scene.Scene`.
    settings : RenderSettings or None (= defaults: effects 'AUTO').
    caster, lights : the renderer's ray caster and LightSet, reused by the
        probe; built here when omitted.
    probe : cast the photon probe (a few thousand rays); False = geometric
        tests only (used when no caster can be built).

    Returns
    -------
    dict, JSON-ready:
    ``motion_blur``, ``caustics``, ``indirect``, ``time_dependent`` : bool.
    ``reasons`` : list of str, one or more per effect, human-readable.
    ``estimator`` : the estimator the render uses ('STANDARD' when not time dependent).
    ``effects`` : 'AUTO' or 'MANUAL'.
    ``details`` : dict -- ``shutter_frames``, ``moving_objects``, ``deforming_objects``,
        ``camera_moves``, ``moving_lights``, ``specular_objects``, ``diffuse_objects``,
        ``self_reflecting_objects``, ``lights`` (power > 0), ``dark_lights``,
        ``lights_reaching_specular`` {light: [objects]}, ``lit_diffuse_objects``,
        ``probe`` (photon counts, or None).
    """
    effects = str(getattr(settings, "effects", "AUTO") or "AUTO").upper() if settings is not None else "AUTO"
    inst_names = [inst.name for inst in scene.instances]
    shutter_open = not scene.shutter.is_instant

    def per_mesh(fn, i: int):
        """fn(mesh of instance i), once per distinct mesh (:func:`mesh_fact`)."""
        return mesh_fact(fn, scene.meshes[scene.instances[i].mesh])
    reasons: list[str] = []

    # -- Motion within the shutter --------------------------------------------------------
    # The scene's lights, the emissive meshes (a lamp shade, a TV screen: LightSet's MESH
    # entries, in its order), then the world when it shines (it lights every object it can see)
    if lights is not None:
        emissive = [l for l in lights.lights if l.type == "MESH"]
    else:
        from .lights import mesh_lights
        emissive = mesh_lights(scene)
    plan_lights = list(scene.lights) + emissive + ([world_light(scene)] if scene.world.shines else [])
    emits = [l.power > 0 and bool(np.any(np.asarray(l.color, float) > 0)) for l in plan_lights]
    moving = [i for i, inst in enumerate(scene.instances)
              if not inst.transform.is_static and not scene.meshes[inst.mesh].is_deforming]
    deforming = [i for i, inst in enumerate(scene.instances) if scene.meshes[inst.mesh].is_deforming]
    # a deforming mesh that also moves rigidly is listed once, as deforming
    camera_moves = not scene.camera.transform.is_static
    moving_lights = [li for li, l in enumerate(plan_lights) if not l.transform.is_static and emits[li]]
    something_moves = bool(moving or deforming or camera_moves or moving_lights)
    lighting_moves = bool(moving or deforming or moving_lights)
    motion_blur = shutter_open and something_moves
    if not something_moves:
        reasons.append("motion_blur: off (nothing moves: objects, meshes, camera and lights are static)")
    elif not shutter_open:
        reasons.append("motion_blur: off (the shutter has zero length; motion is ignored)")
    else:
        what = ([f"objects {_names(inst_names[i] for i in moving)[:4]}"] if moving else []) \
            + ([f"deforming {_names(inst_names[i] for i in deforming)[:4]}"] if deforming else []) \
            + (["the camera"] if camera_moves else []) \
            + ([f"lights {_names(plan_lights[i].name for i in moving_lights)[:4]}"] if moving_lights else [])
        reasons.append(f"motion_blur: moving within the {scene.shutter.length:g}-frame shutter: {', '.join(what)}")

    # -- Specular objects, diffuse objects, lights ----------------------------------------
    delta_mat, diffuse_mat = _material_kinds(scene)
    spec_inst, diff_inst = [], []
    for i, inst in enumerate(scene.instances):
        mats = per_mesh(_mesh_materials, i)
        if mats.size == 0 or np.asarray(scene.meshes[inst.mesh].triangles).shape[0] == 0:
            continue
        if np.any(delta_mat[mats]):
            spec_inst.append(i)
        if np.any(diffuse_mat[mats]):
            diff_inst.append(i)
    emitting = [li for li, e in enumerate(emits) if e]
    dark = [li for li, e in enumerate(emits) if not e]
    spheres = {i: _bounding_sphere(scene, scene.instances[i]) for i in spec_inst}
    spheres = {i: s for i, s in spheres.items() if s is not None}
    # Geometric reach: a light's cone / side faces the specular object's bounding sphere
    geo_reach = {li: {i for i, (c, r) in spheres.items() if _light_faces(plan_lights[li], c, r)}
                 for li in emitting}
    geo_reach = {li: s for li, s in geo_reach.items() if s}
    lit_geo = {i for i in diff_inst for li in emitting
               if (s := _bounding_sphere(scene, scene.instances[i])) is not None
               and _light_faces(plan_lights[li], *s)}

    # -- Photon probe through the real geometry (occlusion, closed objects) ----------------
    probe_info = None
    reach, lit_diffuse = geo_reach, lit_geo
    if probe and emitting and (spheres or diff_inst):
        if lights is None:
            from .lights import LightSet
            lights = LightSet(scene)
        if caster is None:
            from .raycast import make_caster
            caster = make_caster(scene)
        targets = {i: spheres[i] for i in sorted({i for s in geo_reach.values() for i in s})}
        closed = {i for i in lit_geo if per_mesh(_mesh_is_closed, i)}
        pr = _probe(scene, settings, caster, lights, targets, emitting, set(lit_geo), closed,
                    ls_index=_lightset_index(lights, len(scene.lights) + len(emissive)))
        reach = {li: s for li, s in pr["reach_specular"].items() if s}
        lit_diffuse = pr["lit_diffuse"]
        lit_area = sum(_world_area(scene, i) for i in pr["lit_diffuse"])
        caustic_power = sum(float(np.sum(r["power"], dtype=np.float64)) for r in pr["caustic_records"])
        contrast = caustic_contrast(pr["caustic_records"], pr["direct_diffuse_power"], lit_area)
        probe_info = {"photons_aimed": pr["aimed"], "photons_emitted": pr["emitted"],
                      "caustic_photons_stored": pr["caustic_stored"],
                      "returned_power_fraction": pr["return_power"] / max(pr["emitted_power"], 1e-300),
                      "caustic_power_fraction": caustic_power / max(pr["direct_diffuse_power"], 1e-300),
                      "caustic_contrast": contrast if np.isfinite(contrast) else None}

    # -- Caustics: light -> specular -> diffuse ------------------------------------------
    reached_spec = sorted({i for s in reach.values() for i in s})
    no_path = probe_info is not None and probe_info["caustic_photons_stored"] == 0
    # a caustic whose brightest spot is under CAUSTIC_CONTRAST_MIN of the mean direct irradiance and whose
    # flux is under CAUSTIC_POWER_MIN of the direct light's: not worth a map (the textured room's sky
    # through the window onto a glass ball: 0.04 % of the image, 9 of 33 single-thread seconds)
    faint = (not no_path and probe_info is not None
             and probe_info["caustic_contrast"] is not None
             and probe_info["caustic_contrast"] < CAUSTIC_CONTRAST_MIN
             and probe_info["caustic_power_fraction"] < CAUSTIC_POWER_MIN)
    auto_caustics = bool(reached_spec) and bool(diff_inst) and not no_path and not faint
    if auto_caustics:
        msg = (f"caustics: light reaches specular {_names(inst_names[i] for i in reached_spec)[:4]} "
               f"and diffuse {_names(inst_names[i] for i in diff_inst)[:4]} can receive it")
        if probe_info is not None:
            msg += f" (probe: {probe_info['caustic_photons_stored']} of {probe_info['photons_aimed']} aimed photons landed)"
        reasons.append(msg)
    elif not spec_inst:
        reasons.append("caustics: off (no specular object: no clear glass, smooth mirror or smooth coat)")
    elif not emitting:
        reasons.append("caustics: off (no light with power > 0)")
    elif not diff_inst:
        reasons.append("caustics: off (no diffuse surface to receive focused light)")
    elif faint and reached_spec:
        reasons.append(f"caustics: off (light reaches {_names(inst_names[i] for i in reached_spec)[:4]} but the "
                       f"caustic is faint: its brightest spot in the probe is "
                       f"{100 * probe_info['caustic_contrast']:.2g} % of the mean direct irradiance on diffuse "
                       f"surfaces (under {100 * CAUSTIC_CONTRAST_MIN:g} %), and it carries "
                       f"{100 * probe_info['caustic_power_fraction']:.2g} % of the direct light's power (under "
                       f"{100 * CAUSTIC_POWER_MIN:g} %))")
    elif reached_spec:
        reasons.append(f"caustics: off (light reaches {_names(inst_names[i] for i in reached_spec)[:4]} but none of "
                       f"{probe_info['photons_aimed']} probe photons aimed at it went on to a diffuse surface)")
    else:
        reasons.append(f"caustics: off (no light reaches the specular objects "
                       f"{_names(inst_names[i] for i in spec_inst)[:4]})")

    # -- Indirect: diffuse -> diffuse ------------------------------------------------------
    self_refl = [i for i in diff_inst if per_mesh(self_reflecting, i)]
    lit = sorted(lit_diffuse)
    returned = probe_info["returned_power_fraction"] if probe_info is not None else 0.0
    geometric = bool(lit) and (len(diff_inst) >= 2 or any(i in self_refl for i in lit))
    # (the probe's global-map photons: light that came back onto diffuse geometry after a diffuse
    # bounce, e.g. through a glass or water plane and back off its underside)
    auto_indirect = geometric or (bool(diff_inst) and returned >= PROBE_RETURN_MIN)
    if geometric:
        why = (f"{len(diff_inst)} diffuse objects" if len(diff_inst) >= 2
               else f"{_names(inst_names[i] for i in lit if i in self_refl)[:2]} can see itself")
        reasons.append(f"indirect: light reaches diffuse {_names(inst_names[i] for i in lit)[:4]} and {why}")
    elif auto_indirect:
        reasons.append(f"indirect: specular {_names(inst_names[i] for i in spec_inst)[:2]} send light back onto "
                       f"diffuse {_names(inst_names[i] for i in diff_inst)[:2]} (L D S+ D; probe: "
                       f"{100 * returned:.1f} % of the emitted power came back)")
    elif not diff_inst:
        reasons.append("indirect: off (no diffuse surface)")
    elif not emitting:
        reasons.append("indirect: off (no light with power > 0)")
    elif not lit:
        reasons.append("indirect: off (no light reaches a diffuse surface, or only the inside of a closed one)")
    else:
        reasons.append(f"indirect: off (one convex diffuse object {_names(inst_names[i] for i in diff_inst)[:1]}: "
                       "light cannot bounce from it onto diffuse geometry)")

    # -- MANUAL override ---------------------------------------------------------------------
    caustics, indirect = auto_caustics, auto_indirect
    if effects == "MANUAL":
        caustics, indirect = bool(settings.caustics), bool(settings.indirect)
        reasons.append(f"effects MANUAL: caustics {'on' if caustics else 'off'}, "
                       f"indirect {'on' if indirect else 'off'} as set (automatic choice: "
                       f"caustics {'on' if auto_caustics else 'off'}, indirect {'on' if auto_indirect else 'off'})")

    # -- Cycles' diffuse bounce budget: 0 is direct light only -----------------------------------
    if settings is not None and int(getattr(settings, "diffuse_bounces", 4)) == 0 and (caustics or indirect):
        caustics = indirect = False
        reasons.append("caustics, indirect: off (diffuse_bounces = 0: direct light only, as in Cycles; a camera "
                       "vertex reading a photon map makes a diffuse bounce)")

    # -- Time dependence -----------------------------------------------------------------------
    time_dependent = shutter_open and lighting_moves and (caustics or indirect)
    if time_dependent:
        reasons.append("time_dependent: photon-lit geometry or lights move in the shutter: photons carry time")
    elif not (caustics or indirect):
        reasons.append("time_dependent: off (no photon map to time-stamp)")
    elif shutter_open and camera_moves:
        reasons.append("time_dependent: off (only the camera moves: lighting is the same at every instant, "
                       "the STANDARD estimate is exact)")
    else:
        reasons.append("time_dependent: off (static lighting: the STANDARD estimate is exact)")

    estimator = str(getattr(settings, "estimator", "TEMPORAL")) if settings is not None else "TEMPORAL"
    if not time_dependent:
        estimator = "STANDARD"
    details = {
        "shutter_frames": float(scene.shutter.length),
        "moving_objects": _names(inst_names[i] for i in moving),
        "deforming_objects": _names(inst_names[i] for i in deforming),
        "camera_moves": bool(camera_moves),
        "moving_lights": _names(plan_lights[i].name for i in moving_lights),
        "specular_objects": _names(inst_names[i] for i in spec_inst),
        "diffuse_objects": _names(inst_names[i] for i in diff_inst),
        "self_reflecting_objects": _names(inst_names[i] for i in self_refl),
        "lights": _names(plan_lights[i].name for i in emitting),
        "dark_lights": _names(plan_lights[i].name for i in dark),
        "lights_reaching_specular": {plan_lights[li].name: _names(inst_names[i] for i in sorted(s))
                                     for li, s in sorted(reach.items())},
        "lit_diffuse_objects": _names(inst_names[i] for i in lit),
        "probe": probe_info,
    }
    return {"motion_blur": bool(motion_blur), "caustics": bool(caustics), "indirect": bool(indirect),
            "time_dependent": bool(time_dependent), "reasons": reasons, "estimator": estimator,
            "effects": effects, "details": details}


def apply_plan(settings, plan: dict):
    """The settings the renderer acts on: what the plan rules out costs nothing.

    * no caustics -> ``photons_caustic = 0`` (no caustic map, no caustic look-ups);
    * no indirect -> ``photons_global = 0``;
    * not time dependent -> ``estimator = 'STANDARD'`` (exact for static lighting).

    With ``effects='MANUAL'`` the plan already holds ``settings.caustics`` /
    ``settings.indirect``.  ``settings`` itself is not modified.
    """
    changes = {}
    if not plan["caustics"]:
        changes["photons_caustic"] = 0
    if not plan["indirect"]:
        changes["photons_global"] = 0
    if not plan["time_dependent"] and settings.method in ("PHOTON", "PROGRESSIVE"):
        changes["estimator"] = "STANDARD"
    return settings.replace(**changes) if changes else settings


def plan_summary(plan: dict) -> str:
    """One line: ``motion blur, caustics (estimator STANDARD)`` or ``nothing beyond direct light``."""
    on = [k.replace("_", " ") for k in EFFECT_KEYS if plan.get(k)]
    text = ", ".join(on) if on else "direct light only"
    return f"{text} (estimator {plan.get('estimator', '?')})"


def format_plan(plan: dict) -> str:
    """Human-readable plan: one ``effect: yes/no`` line each, then the reasons and details."""
    lines = [f"{k:15s} {'yes' if plan.get(k) else 'no'}" for k in EFFECT_KEYS]
    if "estimator" in plan:
        lines.append(f"{'estimator':15s} {plan['estimator']}")
    lines += ["", "why:"] + [f"  - {r}" for r in plan.get("reasons", [])]
    details = plan.get("details") or {}
    if details:
        lines += ["", "details:"] + [f"  {k}: {json.dumps(v)}" for k, v in details.items()]
    return "\n".join(lines)
