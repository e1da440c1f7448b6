"""A new scene never compiles a new kernel: materials, lights and motion reach the kernels as data.

numba compiles a kernel once per distinct argument-type signature.  If a scene
could change a signature (an int32 array where an int64 one was seen, a
read-only or non-contiguous array, a Python int where a float was passed),
every such scene would pay a compile of tens of seconds.  Here every kernel
is warmed up on the scenes of ``kernel_scenes``; then scenes never seen
before (other materials, light mixes, counts, resolutions, sample counts,
photon budgets, a transparent film) must not add a signature to any kernel
that already had one.
"""
from __future__ import annotations

import dataclasses
import importlib
import pkgutil

import numpy as np

import stpm_core.kernels
from kernel_scenes import kernel_scenes
from scenes import box_mesh, look_at, make_scene, moving, persp_camera, plane_mesh, point_light, sphere_mesh, translate
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


# The procedural textures' public functions are thin wrappers meant to be specialised per caller
# (Python, tests, other argument types): they convert and call the one-signature implementations
# (``procedural._noise_texture`` ...), which this test does check.
WRAPPERS = {f"procedural.{n}" for n in ("noise_texture", "voronoi_texture", "wave_texture", "brick_texture",
                                        "magic_texture", "white_noise_texture")}


def _dispatchers() -> dict:
    """name -> numba dispatcher of every kernel in stpm_core.kernels (but the WRAPPERS)."""
    out = {}
    for mod in pkgutil.iter_modules(stpm_core.kernels.__path__):
        m = importlib.import_module(f"stpm_core.kernels.{mod.name}")
        for name, obj in vars(m).items():
            if hasattr(obj, "signatures") and hasattr(obj, "py_func"):
                home = f"{obj.py_func.__module__.rsplit('.', 1)[-1]}.{obj.py_func.__name__}"
                if home not in WRAPPERS:                 # (also when imported into another module)
                    out[f"{mod.name}.{name}"] = obj
    return out


def _deforming_sphere():
    """A smooth sphere squashed across the shutter: positions and normals per step (the shadow
    terminator's keyed arrays, ``paths.terminator_rows``)."""
    m = sphere_mesh(0.35, 6, 12, material=0)
    V = np.asarray(m.vertices, np.float32)
    m.vertices = np.stack([V, V * np.float32([1.3, 1.0, 0.6])])
    m.vertex_times = np.array([0.0, 1.0])
    N = np.asarray(m.normals, np.float32)
    N1 = N * np.float32([1 / 1.3, 1.0, 1 / 0.6])
    m.normals = np.stack([N, N1 / np.linalg.norm(N1, axis=-1, keepdims=True)]).astype(np.float32)
    return m


def _new_scenes():
    rng = np.random.default_rng(12)
    mats = [Material(base_color=rng.random(3), roughness=float(r), metallic=float(m), transmission=float(t),
                     specular=float(s), ior=1.3 + float(rng.random()))
            for r, m, t, s in [(0.2, 0.0, 0.0, 0.3), (0.0, 1.0, 0.0, 0.0), (0.6, 0.5, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0),
                               (0.05, 0.0, 0.0, 0.0)]] + [Material.emitter((1.0, 2.0, 3.0))]
    objs = [plane_mesh(6.0), (sphere_mesh(0.4, 6, 12, material=3), moving((0, 0, 0.5), (0.3, 0.2, 0.6))),
            (box_mesh(material=1), translate(1.2, 0.0, 0.5)), (box_mesh(material=2), translate(-1.2, 0.3, 0.4)),
            (box_mesh((-0.1, -0.1, 0), (0.1, 0.1, 0.1), material=5), translate(0.0, 1.2, 1.5)),
            (sphere_mesh(0.3, 6, 12, material=4), translate(0.5, -1.0, 0.3)),
            (_deforming_sphere(), translate(-0.6, -1.2, 0.4))]
    lights = [Light(type="SPOT", power=400.0, spot_size=0.6, spot_blend=0.2, radius=0.05,
                    transform=MotionTransform.static(look_at((1, -2, 3), (0, 0, 0)))),
              Light(type="AREA", shape="ELLIPSE", size=0.7, size_y=0.3, power=90.0,
                    transform=moving((0, 0, 2.5), (0.2, 0, 2.6))),
              point_light((-1.0, 1.0, 2.0), 250.0, radius=0.1)]
    cam = persp_camera((0.3, -5.0, 3.0), (0, 0, 0.3), lens=28.0)
    lens = dataclasses.replace(cam, aperture_radius=0.05, focus_distance=5.0, aperture_blades=6)   # depth of field
    yield make_scene(objs, mats, lens, lights, world=(0.02, 0.02, 0.03), resolution=(19, 11),
                     shutter=Shutter(3.0, 3.25)), RenderSettings(samples=1, photons_caustic=3000, photons_global=2000,
                                                                 k_nearest=8, seed=99, threads=2, estimator="KD4D",
                                                                 final_gather_samples=3)
    yield make_scene(objs[:3], mats[:4], cam, lights[1:], resolution=(13, 17), metadata={"film_transparent": True},
                     shutter=Shutter(1.0, 1.0)), RenderSettings(samples=3, photons_caustic=0, photons_global=1500,
                                                                k_nearest=5, seed=1, threads=1, filter_width=0.0)


def test_new_scenes_compile_nothing_new():
    for _, scene, settings in kernel_scenes():
        render(scene, settings)                    # every kernel sees its usual argument types
    disp = _dispatchers()
    assert len(disp) >= 20
    before = {k: len(d.signatures) for k, d in disp.items()}
    for scene, settings in _new_scenes():
        render(scene, settings)
    grew = {k: (before[k], len(d.signatures)) for k, d in disp.items() if before[k] and len(d.signatures) > before[k]}
    assert not grew, f"kernels compiled again for a new scene (signatures before, after): {grew}"
    # Stronger: over all these scenes every kernel has compiled exactly one version (a read-only or
    # a non-contiguous array, an int32 id array or an int where a float went before would add one)
    twice = {k: [str(s) for s in d.signatures] for k, d in disp.items() if len(d.signatures) > 1}
    assert not twice, f"kernels compiled for more than one argument type: {twice}"
