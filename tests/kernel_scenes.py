"""Small scenes that together reach every branch of the shading kernels.

Each entry of :func:`kernel_scenes` is ``(name, scene, settings)``: every light
type and shape (point, spot with blend and radius, soft and hard falloff,
square / rectangle / disc / ellipse areas, sun with and without an angle,
emissive meshes, the world), every lobe (diffuse, coat, rough and mirror
metal, clear and rough glass), motion of objects, lights and the camera,
a deforming emitter, photon maps with each estimator, the accumulation
buffer and a transparent film.  Used by tests/test_kernel_paths.py (kernels
against the numpy oracle) and by the before/after check of a kernel change
(``python tests/kernel_scenes.py OUT.npz`` renders them all into one file).
"""
from __future__ import annotations

import sys

import numpy as np

from scenes import box_mesh, look_at, make_scene, moving, persp_camera, plane_mesh, point_light, sphere_mesh, translate
from stpm_core.motion import MotionTransform
from stpm_core.scene import Light, Material, Mesh
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

__all__ = ["kernel_scenes"]


def _rot_z(angle: float, pos=(0.0, 0.0, 0.0)) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    M = translate(*pos)
    M[:2, :2] = [[c, -s], [s, c]]
    return M


def _materials():
    return [
        Material(base_color=np.array([0.7, 0.7, 0.7]), roughness=0.5, name="floor"),
        Material(base_color=np.array([0.8, 0.3, 0.2]), specular=0.5, roughness=0.0, name="coated"),
        Material(base_color=np.array([0.9, 0.8, 0.5]), metallic=1.0, roughness=0.3, name="rough_metal"),
        Material(base_color=np.array([0.95, 0.95, 0.95]), metallic=1.0, roughness=0.0, name="mirror"),
        Material(base_color=np.array([1.0, 1.0, 1.0]), transmission=1.0, roughness=0.0, ior=1.5, name="glass"),
        Material(base_color=np.array([0.9, 1.0, 0.9]), transmission=1.0, roughness=0.2, ior=1.33, name="rough_glass"),
        Material(base_color=np.zeros(3), emission=np.array([4.0, 3.0, 2.0]), name="emitter"),
        Material(base_color=np.array([0.3, 0.6, 0.3]), specular=0.5, roughness=0.4, name="rough_coat"),
    ]


def _objects(moving_box: bool = False):
    box_tr = moving((-0.6, 0.0, 0.5), (0.6, 0.0, 0.5)) if moving_box else translate(0.0, 0.0, 0.5)
    return [
        plane_mesh(8.0, material=0, name="floor"),
        (box_mesh(material=1, name="box"), box_tr),
        (sphere_mesh(0.5, 8, 16, material=2, name="metal"), translate(1.4, 0.3, 0.5)),
        (sphere_mesh(0.45, 8, 16, material=4, name="glass"), translate(-1.3, 0.4, 0.6)),
        (sphere_mesh(0.35, 8, 16, material=3, name="mirror"), translate(0.2, 1.3, 0.35)),
        (box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 0.6), material=5, name="frosted"), translate(0.6, -1.2, 0.0)),
        (box_mesh((-0.2, -0.2, 0.0), (0.2, 0.2, 0.4), material=7, name="rough_coat"), translate(-0.7, -1.1, 0.0)),
    ]


def _camera():
    return persp_camera((0.0, -6.0, 4.0), (0.0, 0.0, 0.4), lens=35.0)


def _emitter_mesh(deforming: bool) -> Mesh:
    v = np.array([[-0.4, -0.4, 2.5], [0.4, -0.4, 2.5], [0.4, 0.4, 2.6], [-0.4, 0.4, 2.6]], np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    if not deforming:
        return Mesh(vertices=v, triangles=tri, material_ids=np.full(2, 6, np.int32), name="emitter")
    v2 = v.copy()
    v2[:, 0] *= 1.6
    v2[:, 2] += 0.3
    return Mesh(vertices=np.stack([v, v2]), triangles=tri, material_ids=np.full(2, 6, np.int32),
                vertex_times=np.array([0.0, 1.0]), name="emitter")


def kernel_scenes(resolution=(24, 18)):
    """[(name, scene, settings)]: tiny renders covering the shading kernels (a few seconds in all)."""
    out = []
    base = RenderSettings(samples=4, photons_global=0, photons_caustic=0, seed=7, threads=1)
    blur = Shutter(1.0, 1.5)

    def scene(lights, *, world=(0.0, 0.0, 0.0), moving_box=False, shutter=None, metadata=None, extra=()):
        return make_scene(_objects(moving_box) + list(extra), _materials(), _camera(), lights, world=world,
                          resolution=resolution, shutter=shutter, metadata=metadata)

    # -- Point lights: true point, sphere, soft disc; seen through the mirror ---------------
    out.append(("point", scene([point_light((1.0, -1.0, 3.0), 600.0)]), base))
    out.append(("point_radius", scene([
        Light(type="POINT", power=500.0, radius=0.3, use_soft_falloff=False,
              transform=MotionTransform.static(translate(-1.0, 0.5, 2.5))),
        Light(type="POINT", power=300.0, color=np.array([0.5, 0.7, 1.0]), radius=0.2, use_soft_falloff=True,
              transform=MotionTransform.static(translate(1.5, 1.0, 2.0)))],
        metadata={"light_visible_camera": [True, False]}), base))
    # -- Spots: hard and blended, one moving and turning -------------------------------------
    spin = MotionTransform(times=np.array([0.0, 0.5, 1.0]),
                           matrices=np.stack([look_at((2.0, -2.0, 3.0), (0.0, 0.0, 0.0)) @ _rot_z(a)
                                              for a in (0.0, 0.3, 0.7)]))
    out.append(("spot", scene([
        Light(type="SPOT", power=900.0, spot_size=0.8, spot_blend=0.0,
              transform=MotionTransform.static(look_at((-2.0, -1.0, 3.5), (0.0, 0.0, 0.0)))),
        Light(type="SPOT", power=900.0, spot_size=1.0, spot_blend=0.5, radius=0.1, transform=spin)],
        shutter=blur), base))
    # -- Area lights of every shape (one moving) ---------------------------------------------
    out.append(("area", scene([
        Light(type="AREA", power=300.0, shape="SQUARE", size=1.0,
              transform=MotionTransform.static(look_at((0.0, -1.5, 3.0), (0.0, 0.0, 0.0)))),
        Light(type="AREA", power=200.0, shape="RECTANGLE", size=2.0, size_y=0.5,
              transform=moving((1.5, 0.0, 2.5), (2.0, 0.5, 2.5))),
        Light(type="AREA", power=150.0, shape="DISK", size=0.8,
              transform=MotionTransform.static(look_at((-2.0, 0.0, 2.0), (0.0, 0.0, 0.0)))),
        Light(type="AREA", power=150.0, shape="ELLIPSE", size=1.2, size_y=0.4, color=np.array([1.0, 0.6, 0.3]),
              transform=MotionTransform.static(look_at((0.0, 2.0, 2.0), (0.0, 0.0, 0.0))))],
        shutter=blur), base))
    # -- Sun with an angle (0.5 rad: its cone seen in the mirror, glass and metal), plus the world; a transparent film
    out.append(("sun_world", scene([
        Light(type="SUN", power=3.0, angle=0.5, transform=MotionTransform.static(look_at((1, -1, 2), (0, 0, 0))))],
        world=(0.05, 0.06, 0.08), metadata={"film_transparent": True}), base))
    # -- Emissive meshes: static and deforming ------------------------------------------------
    out.append(("mesh_lights", scene([], extra=[(_emitter_mesh(False), translate(-1.0, 0.0, 0.0)),
                                                (_emitter_mesh(True), moving((1.0, 0.0, 0.0), (1.2, 0.2, 0.0)))],
                                     shutter=blur), base))
    # -- Photon maps: caustics and indirect with each estimator, a moving receiver -------------
    lights = [point_light((0.5, -0.5, 3.0), 800.0),
              Light(type="SUN", power=2.0, transform=MotionTransform.static(look_at((-1, -1, 3), (0, 0, 0))))]
    photons = base.replace(photons_caustic=20_000, photons_global=20_000, k_nearest=20)
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        out.append((f"photons_{est.lower()}", scene(lights, moving_box=True, shutter=blur),
                    photons.replace(estimator=est)))
    # -- Accumulation buffer --------------------------------------------------------------------
    out.append(("accumulation", scene(lights, moving_box=True, shutter=blur),
                photons.replace(method="ACCUMULATION", accumulation_steps=2, photons_caustic=5000,
                                photons_global=5000)))
    # -- A moving camera --------------------------------------------------------------------------
    s = scene([point_light((1.0, -1.0, 3.0), 600.0)], shutter=blur)
    s.camera.transform = MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack(
        [look_at((0.0, -6.0, 4.0), (0.0, 0.0, 0.4)), look_at((0.5, -6.0, 4.0), (0.3, 0.0, 0.4))]))
    out.append(("moving_camera", s, base))
    return out


def render_all(path: str) -> None:
    """Render every kernel scene and save the passes to one .npz (name/pass keys)."""
    from stpm_core.render import render

    arrays = {}
    for name, scene, settings in kernel_scenes():
        res = render(scene, settings)
        for p, img in res.passes.items():
            arrays[f"{name}/{p}"] = img
        print(name, float(res.passes["Combined"][..., :3].mean()), flush=True)
    np.savez_compressed(path, **arrays)


if __name__ == "__main__":
    render_all(sys.argv[1])
