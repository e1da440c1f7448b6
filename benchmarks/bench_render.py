"""Full-tracer throughput: camera + shadow rays per second through
``integrator.trace_image`` next to raw embreex ``run()`` on the very same rays.

Scene: :func:`benchmarks.bench_rays.bench_scene` (about 107k triangles: an
82k-triangle icosphere on a 20k-triangle floor grid, four small icospheres),
one diffuse material, a point light, a pinhole camera; 320 x 240 pixels at
16 samples per pixel, no photons (Combined = Direct + world; the grey world is also a light:
one more NEE sample and shadow ray per shading point, since 2026-11-25).  Two variants:

* ``static``: nothing moves;
* ``motion``: the four small spheres translate and turn across an open
  shutter (every camera sample has its own time);
* ``crowd_static`` / ``crowd_motion``: a floor and 200 small spheres (1280
  triangles each, each its own Mesh, as Blender exports duplicates), still
  or each moving and turning: many moving objects.

Per variant:

1. the tracer renders once with a caster wrapper that records every ray it is
   asked to cast (origins, directions, tmax, kind), not timed;
2. in each of several interleaved rounds, the tracer renders again
   (deterministic: the same rays), timed with ``threads=1`` (CPU seconds of
   the tracing thread: the machine is shared), and
3. the recorded rays go straight through raw embreex ``run()`` (float32,
   batches of 8192, INTERSECT for camera rays, OCCLUDED with tmax for shadow
   rays) against one world-space scene at time 0: the ceiling a pure-embree
   tracer could reach on this machine.

Reported: Mrays/s of the tracer (camera + shadow rays / CPU s), of raw embree
on the same rays, ``tracer_over_raw`` and ``motion_over_static_cost`` (cost
per ray, moving over static), plus the tracer's split between ray casting
(CPU seconds inside the caster's calls) and everything else (sampling,
shading, film).
Targets (issue 2): tracer_over_raw >= 0.5, motion_over_static_cost <= 1.5
(``crowd_motion_over_static_cost`` is the same ratio for many moving objects).
``numba`` names the numba version the tracer's kernels (``stpm_core.kernels``) ran on; there is
no numpy path to measure any more (its code is the test oracle ``tests/oracles/integrator_numpy``).
"""
from __future__ import annotations

import time

import numpy as np

from stpm_core.motion import MotionTransform
from stpm_core.raycast.build import embree_available
from stpm_core.scene import Camera, Light, Material, World
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

from stpm_core.scene import Instance, Scene

from .bench_rays import _mesh, _trs, bench_scene, grid, icosphere

__all__ = ["run", "render_scene", "RecordingCaster"]

WIDTH, HEIGHT, SPP = 320, 240, 16


def _look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world matrix looking from eye to target (local -Z forward)."""
    eye, target, up = (np.asarray(a, float) for a in (eye, target, up))
    f = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(f, up)
    x /= np.linalg.norm(x)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, np.cross(x, f), -f, eye
    return M


CROWD = 200          # small spheres of the crowd variants


def crowd_scene(moving: bool) -> Scene:
    """A floor and CROWD small icospheres (1280 triangles each), each its own Mesh (as Blender
    exports duplicated objects), moving 0.3 m and turning during the shutter when ``moving``."""
    rng = np.random.default_rng(11)
    ball = icosphere(3)
    floor = _mesh(*grid(100, 10.0))
    meshes, inst = [floor], [Instance(0)]
    for k in range(CROWD):
        p0 = np.array([*rng.uniform(-4.0, 4.0, 2), 0.3])
        if moving:
            tr = MotionTransform(np.array([0.0, 1.0]), np.stack([_trs(p0, 0.0, 0.25),
                                                                 _trs(p0 + [0.3, 0.1, 0.0], 0.8, 0.25)]))
        else:
            tr = MotionTransform.static(_trs(p0, 0.0, 0.25))
        meshes.append(_mesh(*ball, smooth=True))
        inst.append(Instance(k + 1, tr))
    return Scene(meshes=meshes, instances=inst, materials=[Material()])


def render_scene(moving: bool, crowd: bool = False):
    """The ~107k-triangle benchmark scene (or the crowd) with camera, light, material and shutter."""
    sc = crowd_scene(moving) if crowd else bench_scene(moving)
    sc.materials = [Material.diffuse((0.7, 0.7, 0.7))]
    sc.camera = Camera(type="PERSP", transform=MotionTransform.static(_look_at((0, -7, 4), (0, 0, 0.5))),
                       lens=35.0)
    M = np.eye(4)
    M[:3, 3] = (2.0, -2.0, 6.0)
    sc.lights = [Light(type="POINT", power=2000.0, transform=MotionTransform.static(M))]
    sc.world = World(color=np.full(3, 0.05), strength=1.0)
    sc.resolution = (WIDTH, HEIGHT)
    sc.shutter = Shutter(1.0, 1.5) if moving else Shutter(1.0, 1.0)
    return sc


class RecordingCaster:
    """Wraps a caster and keeps a copy of every ray batch it casts."""

    def __init__(self, caster):
        self.caster = caster
        self.stats = caster.stats
        self.batches: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = []

    def intersect(self, o, d, t, tmax=None, guard=None):
        n = np.asarray(o).shape[0]
        tm = np.full(n, np.inf) if tmax is None else np.broadcast_to(np.asarray(tmax, float), (n,))
        self.batches.append(("intersect", np.array(o, float), np.array(d, float), np.array(tm)))
        return self.caster.intersect(o, d, t, tmax, guard=guard)

    def occluded(self, o, d, t, tmax, guard=None):
        self.batches.append(("occluded", np.array(o, float), np.array(d, float),
                             np.array(np.broadcast_to(np.asarray(tmax, float), (np.asarray(o).shape[0],)))))
        return self.caster.occluded(o, d, t, tmax, guard=guard)


class TimingCaster:
    """Wraps a caster and adds up the calling thread's CPU seconds spent in it."""

    def __init__(self, caster):
        self.caster = caster
        self.stats = caster.stats
        self.seconds = 0.0

    def intersect(self, *a, **k):
        t0 = time.thread_time()
        try:
            return self.caster.intersect(*a, **k)
        finally:
            self.seconds += time.thread_time() - t0

    def occluded(self, *a, **k):
        t0 = time.thread_time()
        try:
            return self.caster.occluded(*a, **k)
        finally:
            self.seconds += time.thread_time() - t0


def _trace(scene, caster, threads: int):
    from stpm_core.integrator import trace_image
    from stpm_core.lights import LightSet
    st = RenderSettings(samples=SPP, photons_caustic=0, photons_global=0, seed=0, threads=threads)
    return trace_image(scene, st, caster, LightSet(scene), None)


def _raw_times(es, batches, chunk: int = 8192) -> float:
    """CPU seconds for raw run() over the recorded rays (float32 conversion included)."""
    t0 = time.process_time()
    for kind, o, d, tmax in batches:
        o32, d32 = o.astype(np.float32), d.astype(np.float32)
        far = np.minimum(tmax, 1e37).astype(np.float32)
        for a in range(0, o32.shape[0], chunk):
            sl = slice(a, a + chunk)
            if kind == "intersect":
                es.run(o32[sl], d32[sl], dists=far[sl], output=1)
            else:
                es.run(o32[sl], d32[sl], dists=far[sl], query="OCCLUDED")
    return time.process_time() - t0


def _tracer_times(sc, caster) -> tuple[float, float]:
    """(CPU s of one threads=1 render on this thread, of which inside the caster)."""
    timed = TimingCaster(caster)
    t0 = time.thread_time()
    _trace(sc, timed, threads=1)          # threads=1 traces on this thread
    return time.thread_time() - t0, timed.seconds


def run(rounds: int = 5) -> dict:
    """Measure and return {name: value}; speeds in Mrays/s, times in s, ratios unitless.

    Each of ``rounds`` rounds times, one after the other, the static tracer,
    raw embree on its rays, the motion tracer and raw embree on its rays, so
    a slow spell of the shared machine hits every quantity alike.  Reported:
    the minimum over rounds of each CPU time (noise only adds time) and the
    ratios of those minima; ``*_per_round`` lists each round's own ratio.
    """
    from stpm_core.raycast import make_caster
    from .bench_rays import _raw_embree

    import numba

    out: dict = {"resolution": f"{WIDTH}x{HEIGHT}", "spp": SPP, "numba": numba.__version__, "rounds": rounds}
    if not embree_available():
        out["skipped"] = "embreex not importable"
        return out
    variants = {}
    for variant, moving, crowd in (("static", False, False), ("motion", True, False),
                                   ("crowd_static", False, True), ("crowd_motion", True, True)):
        sc = render_scene(moving, crowd)
        out[f"{'crowd_' if crowd else ''}triangles"] = int(sum(len(sc.meshes[i.mesh].triangles)
                                                              for i in sc.instances))
        caster = make_caster(sc, "embree")
        # 1. Record the rays (not timed); the tracer is deterministic, so every later render casts these
        rec = RecordingCaster(caster)
        _, stats = _trace(sc, rec, threads=1)
        n_cam = sum(o.shape[0] for k, o, _, _ in rec.batches if k == "intersect")
        n_sh = sum(o.shape[0] for k, o, _, _ in rec.batches if k == "occluded")
        out[f"{variant}_camera_rays"] = int(stats.camera_rays)
        out[f"{variant}_bounce_rays"] = int(stats.bounce_rays)
        out[f"{variant}_shadow_rays"] = int(stats.shadow_rays)
        variants[variant] = (sc, caster, rec.batches, _raw_embree(sc), n_cam + n_sh)
    # 2. Interleaved rounds: tracer (CPU s on one thread) and raw embree on the same rays
    times = {v: {"cpu": [], "cast": [], "raw": []} for v in variants}
    for _ in range(rounds):
        for v, (sc, caster, batches, es, _) in variants.items():
            cpu, cast = _tracer_times(sc, caster)
            times[v]["cpu"].append(cpu)
            times[v]["cast"].append(cast)
            times[v]["raw"].append(_raw_times(es, batches))
    for v, (sc, caster, _, _, n) in variants.items():
        t = {k: np.asarray(a) for k, a in times[v].items()}
        i = int(np.argmin(t["cpu"]))
        cpu, cast, raw = float(t["cpu"][i]), float(t["cast"][i]), float(t["raw"].min())
        w0 = time.perf_counter()
        _trace(sc, caster, threads=0)
        wall = time.perf_counter() - w0
        out[f"{v}_tracer_cpu_s"] = cpu
        out[f"{v}_tracer_wall_s_all_threads"] = wall
        out[f"{v}_tracer_casting_s"] = cast
        out[f"{v}_tracer_shading_s"] = cpu - cast
        out[f"{v}_tracer_Mrays_s"] = n / cpu / 1e6
        out[f"{v}_tracer_wall_Mrays_s_all_threads"] = n / wall / 1e6
        out[f"{v}_raw_cpu_s"] = raw
        out[f"{v}_raw_Mrays_s"] = n / raw / 1e6
        out[f"{v}_tracer_over_raw"] = raw / cpu
        out[f"{v}_tracer_over_raw_per_round"] = [round(float(r / c), 3) for r, c in zip(t["raw"], t["cpu"])]
    for moving, static, name in (("motion", "static", "motion_over_static_cost"),
                                 ("crowd_motion", "crowd_static", "crowd_motion_over_static_cost")):
        nm, ns = variants[moving][4], variants[static][4]
        out[name] = (out[f"{moving}_tracer_cpu_s"] / nm) / (out[f"{static}_tracer_cpu_s"] / ns)
        out[f"{name}_per_round"] = [round(float((m / nm) / (s_ / ns)), 3)
                                    for m, s_ in zip(times[moving]["cpu"], times[static]["cpu"])]
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:40s} {v}")
