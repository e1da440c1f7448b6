"""A room lit by an HDRI through a window with a light portal in it, against Cycles (bpy 5.0).

The room of tests/portal_scenes.py built in Blender: the window's portal is an AREA light with
Cycles' ``is_portal`` (and 100 W of power, which a portal does not emit: exported as a light, the
old exporter lit the room with it).  Direct light only (Cycles ``max_bounces = 0``, STPM without
photons): the world's light through the window, sampled through the portal, must match Cycles'
within the noise (``cycles_ref.block_ztest``).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_camera, add_light, fresh  # noqa: E402
from test_cycles_world import hdri_world, write_hdri  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_cycles_paths, render_stpm  # noqa: E402
from portal_scenes import WINDOW, room_mesh  # noqa: E402

W, H = 48, 36
SPP = 64
Z_MAX = 4.5
MEAN_TOL = 0.03


def _room(tmp_path, metal_ball: float = 0.0, sun: float = 200.0, eye=(0.85, -0.8, 1.7), target=(-1.0, 0.6, 0.3),
          lens: float = 14.0):
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    write_hdri(tmp_path / "sky.exr", sun=sun)
    hdri_world(tmp_path / "sky.exr", rotation_z=-20.0)
    mat = bpy.data.materials.new("White")
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.7, 0.7, 0.7, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Specular IOR Level"].default_value = 0.0
    m = room_mesh()
    me = bpy.data.meshes.new("Room")
    me.from_pydata(m.vertices.tolist(), [], m.triangles.tolist())
    me.materials.append(mat)
    obj = bpy.data.objects.new("Room", me)
    scene.collection.objects.link(obj)
    if metal_ball > 0:
        metal = bpy.data.materials.new("Metal")
        q = metal.node_tree.nodes["Principled BSDF"]
        q.inputs["Base Color"].default_value = (0.9, 0.9, 0.9, 1.0)
        q.inputs["Metallic"].default_value = 1.0
        q.inputs["Roughness"].default_value = metal_ball
        bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.2, 0.4), radius=0.4, segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(metal)
    y0, y1, z0, z1 = WINDOW
    portal = add_light("AREA", "Portal", location=(1.0, 0.5 * (y0 + y1), 0.5 * (z0 + z1)), size=y1 - y0,
                       energy=100.0)
    portal.rotation_euler = (0.0, math.radians(90.0), 0.0)     # local -Z -> world -x: into the room
    portal.data.cycles.is_portal = True
    # camera inside, by the window wall, looking at the floor and the far walls (not at the window:
    # a bright background edge would test the pixel filters rather than the light)
    from mathutils import Vector
    eye = Vector(eye)
    cam = add_camera(location=eye, lens=lens)
    cam.rotation_euler = (Vector(target) - eye).to_track_quat("-Z", "Y").to_euler()
    return scene


def test_room_through_a_portal_matches_cycles(tmp_path):
    scene = _room(tmp_path)
    from test_addon_scenes import export_now
    core, _ = export_now()
    assert len(core.portals) == 1 and not core.lights, (core.portals, core.lights)
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=(0, 1, 2))
    stpm, res = render_stpm(scene, samples=SPP, seeds=(0, 1, 2))
    r = block_ztest(stpm, cyc)
    print(f"portal room: {r.summary()}")
    assert cyc.mean() > 0.01
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()


def test_rough_metal_reflecting_the_window_matches_cycles(tmp_path):
    """A rough metal ball reflects the window: next-event samples through the portal and the lobe's
    own samples escaping through it are weighed against each other with the portal mixture's density
    (``lights.world_nee_pdf`` in ``kernels.paths``).  One glossy bounce, no diffuse bounce, in both."""
    # (a sun in a rough mirror gives fireflies in both: a dim one); the camera close to the ball
    scene = _room(tmp_path, metal_ball=0.5, sun=20.0, eye=(-0.7, -0.6, 1.0), target=(0.0, 0.2, 0.45), lens=30.0)
    seeds = (0, 1, 2, 3)
    cyc = render_cycles_paths(scene, tmp_path, samples=SPP // 2, seeds=seeds, diffuse_bounces=0, glossy_bounces=1,
                              transmission_bounces=0, caustics=False)
    stpm, _ = render_stpm(scene, samples=SPP // 2, seeds=seeds, diffuse_bounces=0, glossy_bounces=1)
    r = block_ztest(stpm, cyc)
    print(f"portal room, metal ball: {r.summary()}")
    # measured at 64 samples: |z| max 4.0-4.95, mean ratio 0.998-0.999; with the lobe's samples weighed
    # by the density without portals (the MIS bug this guards against): |z| max 18.9, mean ratio 1.126
    assert r.z_abs_max < 6.0, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < 0.04, r.summary()


def test_portal_flag_and_photon_weights_are_exported_and_drawn(tmp_path):
    """``light.cycles.is_portal`` makes the area light a portal (not a light); ``light.stpm.photon_weight``
    and ``world.stpm.photon_weight`` reach the scene; the light and world panels draw them."""
    from types import SimpleNamespace
    from addon import ui
    from test_addon_scenes import export_now, set_world
    from test_addon_ui import _RecordingLayout
    scene = fresh()
    world = set_world((0.5, 0.5, 0.5))
    world.stpm.photon_weight = 0.25
    lamp = add_light("POINT", "Lamp", location=(0, 0, 1.5), energy=50.0)
    lamp.data.stpm.photon_weight = 3.0
    portal = add_light("AREA", "Portal", location=(1.0, 0.0, 1.2), size=0.8)
    portal.data.cycles.is_portal = True
    add_camera()
    core, _ = export_now()
    assert [l.name for l in core.lights] == ["Lamp"] and [p.name for p in core.portals] == ["Portal"]
    assert core.lights[0].photon_weight == pytest.approx(3.0) and core.world.photon_weight == pytest.approx(0.25)
    assert core.portals[0].type == "AREA" and core.portals[0].size == pytest.approx(0.8)
    drawn = {}
    for cls, ctx in ((ui.STPM_LIGHT_PT_photons, SimpleNamespace(light=portal.data, engine="STPM")),
                     (ui.STPM_WORLD_PT_photons, SimpleNamespace(world=world, engine="STPM"))):
        log = []
        panel = SimpleNamespace(layout=_RecordingLayout(log))
        cls.draw(panel, ctx)
        drawn[cls.__name__] = log
        assert cls.poll(ctx)
    assert drawn == {"STPM_LIGHT_PT_photons": ["is_portal", "photon_weight"],
                     "STPM_WORLD_PT_photons": ["photon_weight"]}
    scene.render.engine = "CYCLES"
