"""Ray-casting throughput: the time-aware caster next to raw embreex ``run()``.

Scene (built in numpy, about 100k triangles): an icosphere (82k triangles)
resting on a 100 x 100 grid floor (20k), plus four small icospheres (1.3k
each).  Three variants with the same geometry:

* ``static``: everything static;
* ``motion``: the four small spheres translate and rotate across the shutter;
* ``motion_big``: the big sphere moves and turns as well (worst case: most
  rays meet a moving instance).

Ray batches, each ray with a random shutter time:

* ``camera``: coherent rays from a pinhole looking at the scene;
* ``shadow``: from points on the floor toward a point light, tmax at the light
  (``occluded``).

Reported (per CPU second, see :func:`_best_of`): Mrays/s of the caster
(embree, numba and, on a subset, numpy; ``embree_*`` uses the fused numba
kernels around embree's ``run()``, ``embree_numpy_*`` the same caster with
its numpy path, ``make_caster(..., fused=False)``: before / after in one run), of raw embreex ``run()`` on the same
rays against one float32 world-space scene at time 0 (no refinement, no
shading), and the ratios motion/static cost and caster/raw speed.  The numba
backend runs on all cores, so it is also reported per wall-clock second
(``*_wall_Mrays_s``, load-dependent), and its first-call JIT compile time with
an empty and with a filled on-disk cache (fresh processes, see
:func:`numba_compile_times`).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from stpm_core.motion import MotionTransform
from stpm_core.raycast import make_caster
from stpm_core.raycast.build import embree_available, make_caster as _make_caster, numba_available
from stpm_core.scene import Instance, Material, Mesh, Scene

__all__ = ["run", "icosphere", "grid", "bench_scene"]


def icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: vertices (V, 3) float64, triangles (20 * 4**level, 3) int32."""
    p = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p],
                  [0, -1, -p], [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], float)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(level):
        # Split each edge once (edges keyed by sorted vertex pair), four children per face
        e = np.sort(np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], 1).reshape(-1, 2), axis=1)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        mid = len(V) + inv.reshape(-1, 3)
        V = np.vstack([V, 0.5 * (V[uniq[:, 0]] + V[uniq[:, 1]])])
        a, b, c = F[:, 0], F[:, 1], F[:, 2]
        ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
        F = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1),
                            np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    return V, F.astype(np.int32)


def grid(n: int, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat n x n quad grid in z = 0, side ``size``, centred: (V, 3), (2 n^2, 3)."""
    x = np.linspace(-size / 2, size / 2, n + 1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    k = (i * (n + 1) + j).ravel()
    F = np.concatenate([np.stack([k, k + n + 1, k + n + 2], 1), np.stack([k, k + n + 2, k + 1], 1)])
    return V, F.astype(np.int32)


def _mesh(V, F, smooth=False) -> Mesh:
    normals = V[F].astype(np.float32) if smooth else None
    return Mesh(vertices=V.astype(np.float32), triangles=F, material_ids=np.zeros(len(F), np.int32),
                normals=normals)


def _trs(t, angle=0.0, s=1.0) -> np.ndarray:
    M = np.eye(4)
    c, si = np.cos(angle), np.sin(angle)
    M[:3, :3] = np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]]) * s
    M[:3, 3] = t
    return M


def bench_scene(moving: bool, big_moves: bool = False) -> Scene:
    """~107k triangles; the four small spheres move when ``moving``, the big one too
    when ``big_moves`` (then 80 % of the triangles are in moving instances)."""
    big = _mesh(*icosphere(6), smooth=True)
    small = _mesh(*icosphere(3), smooth=True)
    floor = _mesh(*grid(100, 10.0))
    if big_moves:
        big_tr = MotionTransform(np.array([0.0, 1.0]), np.stack([_trs([-0.2, 0, 1]), _trs([0.2, 0.1, 1], 0.5)]))
    else:
        big_tr = MotionTransform.static(_trs([0, 0, 1]))
    inst = [Instance(0, big_tr), Instance(2)]
    for k in range(4):
        a = k * np.pi / 2
        p0 = np.array([2.5 * np.cos(a), 2.5 * np.sin(a), 0.5])
        if moving:
            tr = MotionTransform(np.array([0.0, 0.5, 1.0]),
                                 np.stack([_trs(p0, 0.0, 0.4), _trs(p0 + [0.3, 0.2, 0.1], 0.8, 0.4),
                                           _trs(p0 + [0.6, 0.0, 0.0], 1.6, 0.4)]))
        else:
            tr = MotionTransform.static(_trs(p0, 0.0, 0.4))
        inst.append(Instance(1, tr))
    return Scene(meshes=[big, small, floor], instances=inst, materials=[Material()])


def camera_rays(n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole rays from (0, -7, 4) looking at the origin over a 60-degree view, row order."""
    w = int(np.sqrt(n))
    h = n // w
    eye = np.array([0.0, -7.0, 4.0])
    fwd = -eye / np.linalg.norm(eye)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    px, py = np.meshgrid((np.arange(w) + 0.5) / w * 2 - 1, (np.arange(h) + 0.5) / h * 2 - 1)
    d = fwd + np.tan(np.pi / 6) * (px.ravel()[:, None] * right + py.ravel()[:, None] * up)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.broadcast_to(eye, d.shape).copy(), d


def shadow_rays(n: int, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Floor points -> light at (2, -2, 6): origins, unit dirs, tmax = distance."""
    p = np.column_stack([rng.uniform(-5, 5, (n, 2)), np.full(n, 1e-4)])
    L = np.array([2.0, -2.0, 6.0]) - p
    dist = np.linalg.norm(L, axis=1)
    return p, L / dist[:, None], dist


def _best_of(f, repeats: int) -> float:
    """Smallest CPU time of this process over ``repeats`` calls of f (seconds).

    CPU time, not wall time: the development machine is shared, and time spent
    descheduled is not the caster's.  Everything measured here runs on the
    calling thread (embreex ``run()`` is single-threaded), so CPU time is the
    cost of the call.
    """
    best = np.inf
    for _ in range(repeats):
        t0 = time.process_time()
        f()
        best = min(best, time.process_time() - t0)
    return best


def _cpu_and_wall(f) -> tuple[float, float]:
    """CPU seconds of this process (all threads) and wall seconds of one call of f."""
    c0, w0 = time.process_time(), time.perf_counter()
    f()
    return time.process_time() - c0, time.perf_counter() - w0


# Run in a fresh interpreter: import, build a caster on a small scene, first intersect, first occluded
_COMPILE_PROBE = """
import time, json
import numpy as np
t0 = time.perf_counter()
from benchmarks.bench_rays import icosphere, _mesh
from stpm_core.raycast import make_caster
from stpm_core.scene import Instance, Mesh, Scene, Material
from stpm_core.motion import MotionTransform
V, F = icosphere(2)
M1 = np.eye(4); M1[:3, 3] = (0.5, 0, 0)
sc = Scene(meshes=[_mesh(V, F)], instances=[Instance(0), Instance(0, MotionTransform(np.array([0.0, 1.0]),
           np.stack([np.eye(4), M1])))], materials=[Material()])
t1 = time.perf_counter()
c = make_caster(sc, "numba")
t2 = time.perf_counter()
o = np.tile([0.0, -5.0, 0.0], (64, 1)); d = np.tile([0.0, 1.0, 0.0], (64, 1)); u = np.linspace(0, 1, 64)
c.intersect(o, d, u)
t3 = time.perf_counter()
c.occluded(o, d, u, 10.0)
t4 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "build_s": t2 - t1, "intersect_s": t3 - t2, "occluded_s": t4 - t3}))
"""


def _children_cpu():
    """CPU seconds used by finished child processes (None where ``resource`` is missing: Windows)."""
    try:
        import resource
    except ImportError:
        return None
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def numba_compile_times() -> dict:
    """First-use cost of the numba backend in fresh processes: {'cold': {...}, 'warm': {...}}.

    cold = empty on-disk cache (every kernel compiles), warm = the cache the
    cold run left (kernels load).  Each dict: import_s (numpy, stpm_core),
    build_s (first make_caster: BVH build kernel), intersect_s, occluded_s (first
    calls: traversal kernels), total_s (wall seconds, all load-dependent) and
    process_cpu_s (CPU seconds of the whole child process, start-up included).
    """
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=root)
        for kind in ("cold", "warm"):
            cpu0 = _children_cpu()
            r = subprocess.run([sys.executable, "-c", _COMPILE_PROBE], env=env, cwd=root,
                               capture_output=True, text=True, check=True)
            out[kind] = json.loads(r.stdout.strip().splitlines()[-1])
            out[kind]["total_s"] = sum(out[kind].values())
            if cpu0 is not None:
                out[kind]["process_cpu_s"] = _children_cpu() - cpu0
    return out


def _raw_embree(scene: Scene):
    """One float32 world-space embreex scene of all geometry at time 0 (the baseline)."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh
    Vs, Fs, nv = [], [], 0
    for inst in scene.instances:
        m = scene.meshes[inst.mesh]
        M = inst.transform.at(0.0)
        V = np.asarray(m.vertices, float) @ M[:3, :3].T + M[:3, 3]
        Vs.append(V)
        Fs.append(np.asarray(m.triangles) + nv)
        nv += len(V)
    es = rtcs.EmbreeScene()
    TriangleMesh(es, np.vstack(Vs).astype(np.float32), np.vstack(Fs).astype(np.int32))
    return es


def _raw_run(es, o, d, tmax=None, query="INTERSECT", batch=8192):
    """Raw run() over the rays in batches (float32 conversion included)."""
    o32, d32 = o.astype(np.float32), d.astype(np.float32)
    far = None if tmax is None else tmax.astype(np.float32)
    for a in range(0, len(o32), batch):
        sl = slice(a, a + batch)
        if query == "INTERSECT":
            es.run(o32[sl], d32[sl], output=1)
        else:
            es.run(o32[sl], d32[sl], dists=far[sl], query="OCCLUDED")


def run(n_rays: int = 131072, repeats: int = 7, seed: int = 0) -> dict:
    """Measure and return {name: value}; speeds in Mrays/s, ratios unitless.

    Caster and raw embree calls are interleaved and each keeps its best of
    ``repeats`` (the machine is shared: best-of is the least noisy statistic).
    """
    rng = np.random.default_rng(seed)
    out: dict = {}
    scenes = {"static": bench_scene(False), "motion": bench_scene(True), "motion_big": bench_scene(True, True)}
    ntri = sum(len(scenes["static"].meshes[i.mesh].triangles) for i in scenes["static"].instances)
    out["triangles"] = int(ntri)
    out["rays_per_batch"] = int(n_rays)
    co, cd = camera_rays(n_rays, rng)
    so, sd, sdist = shadow_rays(n_rays, rng)
    times = rng.uniform(0, 1, co.shape[0])
    stimes = rng.uniform(0, 1, so.shape[0])
    n_cam, n_sh = co.shape[0], so.shape[0]
    if numba_available():
        # First-use JIT cost in fresh processes (empty / filled on-disk cache)
        for kind, d in numba_compile_times().items():
            for key, v in d.items():
                out[f"numba_first_use_{kind}_{key}"] = v
    backends = [b for b, ok in (("embree", embree_available()), ("numba", numba_available())) if ok]
    if "numba" in backends:
        # Import numba and load the compiled kernels before timing the builds
        tiny = Scene(meshes=[_mesh(*icosphere(0))], instances=[Instance(0)], materials=[Material()])
        make_caster(tiny, "numba").occluded(co[:64], cd[:64], times[:64], 1.0)
    if backends:
        # Every job of every variant in each round, so load changes hit them all alike
        jobs = {}
        # embree with its numpy path (no fused kernels) next to the default fused one
        variants_of = list(backends) + (["embree_numpy"] if "embree" in backends else [])
        for variant, sc in scenes.items():
            for backend in variants_of:
                t0 = time.perf_counter()
                caster = (_make_caster(sc, "embree", fused=False) if backend == "embree_numpy"
                          else make_caster(sc, backend))
                out[f"{backend}_{variant}_build_s"] = time.perf_counter() - t0
                caster.occluded(co[:64], cd[:64], times[:64], 1.0)          # load compiled kernels
                jobs.update({
                    f"{backend}_{variant}_camera": (n_cam, lambda c=caster: c.intersect(co, cd, times)),
                    f"{backend}_{variant}_shadow": (n_sh, lambda c=caster: c.occluded(so, sd, stimes, sdist)),
                    f"{backend}_{variant}_shadow_intersect": (n_sh, lambda c=caster: c.intersect(so, sd, stimes,
                                                                                                    sdist)),
                })
            if "embree" in backends:
                es = _raw_embree(sc)
                jobs.update({
                    f"raw_{variant}_camera": (n_cam, lambda e=es: _raw_run(e, co, cd)),
                    f"raw_{variant}_shadow": (n_sh, lambda e=es: _raw_run(e, so, sd, sdist, "OCCLUDED")),
                })
        best = {k: np.inf for k in jobs}
        best_wall = {k: np.inf for k in jobs}
        for _ in range(repeats):
            for k, (_, f) in jobs.items():
                cpu, wall = _cpu_and_wall(f)
                best[k], best_wall[k] = min(best[k], cpu), min(best_wall[k], wall)
        for k, (n, _) in sorted(jobs.items()):
            out[f"{k}_Mrays_s"] = n / best[k] / 1e6
            if k.startswith("numba"):
                out[f"{k}_wall_Mrays_s"] = n / best_wall[k] / 1e6
    # numpy fallback (PairBVH) on a subset of the camera rays
    m = 2048
    sub = np.linspace(0, n_cam - 1, m).astype(int)
    for variant in ("static", "motion"):
        caster = make_caster(scenes[variant], "numpy")
        s = _best_of(lambda: caster.intersect(co[sub], cd[sub], times[sub]), 1)
        out[f"numpy_{variant}_camera_Mrays_s"] = m / s / 1e6
        s = _best_of(lambda: caster.occluded(so[sub], sd[sub], stimes[sub], sdist[sub]), 1)
        out[f"numpy_{variant}_shadow_Mrays_s"] = m / s / 1e6
    # numpy fallback on a small scene (1.5k triangles: icosphere + floor, moving sphere)
    small = Scene(meshes=[_mesh(*icosphere(3), smooth=True), _mesh(*grid(10, 10.0))],
                  instances=[Instance(0, MotionTransform(np.array([0.0, 1.0]),
                                                         np.stack([_trs([0, 0, 1]), _trs([0.5, 0, 1], 0.5)]))),
                             Instance(1)], materials=[Material()])
    m = 16384
    out["small_scene_triangles"] = 1280 + 200
    for backend in backends + ["numpy"]:
        caster = make_caster(small, backend)
        caster.occluded(co[:64], cd[:64], times[:64], 1.0)
        s = _best_of(lambda: caster.intersect(co[:m], cd[:m], times[:m]), 3)
        out[f"{backend}_small_camera_Mrays_s"] = m / s / 1e6
    if "numba" in backends:
        # numba next to embree (per CPU second) and next to the numpy fallback
        for variant in scenes:
            for kind in ("camera", "shadow"):
                if "embree" in backends:
                    out[f"numba_over_embree_{variant}_{kind}"] = (out[f"numba_{variant}_{kind}_Mrays_s"]
                                                                 / out[f"embree_{variant}_{kind}_Mrays_s"])
        for variant in ("static", "motion"):
            for kind in ("camera", "shadow"):
                out[f"numba_over_numpy_{variant}_{kind}"] = (out[f"numba_{variant}_{kind}_Mrays_s"]
                                                             / out[f"numpy_{variant}_{kind}_Mrays_s"])
    # Ratios (targets: motion cost <= 1.5 x static; caster >= 50 % of raw)
    # (``numpy_path_*``: the same ratios for the embree caster's numpy path, i.e. before fusing)
    if embree_available():
        for tag, name in (("", "embree"), ("numpy_path_", "embree_numpy")):
            for kind in ("camera", "shadow", "shadow_intersect"):
                for variant in ("motion", "motion_big"):
                    out[f"{tag}{variant}_over_static_cost_{kind}"] = (out[f"{name}_static_{kind}_Mrays_s"]
                                                                      / out[f"{name}_{variant}_{kind}_Mrays_s"])
                for variant in scenes:
                    raw = out[f"raw_{variant}_{kind if kind != 'shadow_intersect' else 'shadow'}_Mrays_s"]
                    if kind != "shadow_intersect":
                        out[f"{tag}caster_over_raw_{variant}_{kind}"] = out[f"{name}_{variant}_{kind}_Mrays_s"] / raw
        for variant in scenes:
            for kind in ("camera", "shadow", "shadow_intersect"):
                out[f"fused_speedup_{variant}_{kind}"] = (out[f"embree_{variant}_{kind}_Mrays_s"]
                                                          / out[f"embree_numpy_{variant}_{kind}_Mrays_s"])
    return out
