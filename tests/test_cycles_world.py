"""Environment Texture worlds against Cycles (bpy 5.0): direct-only renders compared block by block.

An HDRI written to an OpenEXR file (a sky gradient, a warm ground, a small sun), loaded by an
Environment Texture turned by a Mapping node, lights a floor, a sphere and a box seen with some
sky behind them: background, sun shadow and sky light must match Cycles' within the noise
(``cycles_ref.block_ztest``), at a few seconds per render.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
oiio = pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_camera, add_mesh, fresh  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402

W, H = 64, 48
SPP = 64
Z_MAX = 4.5
MEAN_TOL = 0.02


def write_hdri(path, w: int = 128, h: int = 64, sun_uv=(0.62, 0.72), sun: float = 2000.0) -> np.ndarray:
    """A small equirectangular HDRI (h, w, 3) float32, row 0 at the top as files store it: sky
    gradient, warm ground, a 2 x 2 texel sun (about 5 degrees across) at sun_uv (Cycles' u, v)."""
    v = 1.0 - (np.arange(h) + 0.5) / h                    # file row 0 = top = v near 1
    img = np.empty((h, w, 3), np.float32)
    sky = np.clip((v - 0.5) * 2.0, 0.0, 1.0)
    img[...] = (0.3 + 0.7 * sky)[:, None, None] * np.array([0.35, 0.5, 0.9], np.float32)
    img[v < 0.5] = np.array([0.12, 0.09, 0.06], np.float32)
    j, i = int((1.0 - sun_uv[1]) * h), int(sun_uv[0] * w)
    img[j:j + 2, i:i + 2] = sun
    spec = oiio.ImageSpec(w, h, 3, "float")
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(img)
    out.close()
    return img


def hdri_world(path, rotation_z: float = 30.0, interpolation: str = "Linear", strength: float = 1.0):
    """A world: Texture Coordinate (Generated) -> Mapping (Z rotation) -> Environment Texture -> Background."""
    world = bpy.data.worlds.new("HDRI")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    t = world.node_tree
    bg = t.nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    env = t.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(path))
    env.interpolation = interpolation
    coord = t.nodes.new("ShaderNodeTexCoord")
    mp = t.nodes.new("ShaderNodeMapping")
    mp.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rotation_z))
    t.links.new(coord.outputs["Generated"], mp.inputs["Vector"])
    t.links.new(mp.outputs["Vector"], env.inputs["Vector"])
    t.links.new(env.outputs["Color"], bg.inputs["Color"])
    bpy.context.scene.world = world
    return world


def _scene(tmp_path, **world):
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    write_hdri(tmp_path / "sky.exr")
    hdri_world(tmp_path / "sky.exr", **world)
    mat = bpy.data.materials.new("White")
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Specular IOR Level"].default_value = 0.0
    add_mesh("plane", "Floor", material=mat, size=6.0)
    add_mesh("sphere", "Ball", location=(0.6, 0.3, 0.5), material=mat, radius=0.5, segments=32, ring_count=16)
    add_mesh("cube", "Box", location=(-0.7, -0.2, 0.35), material=mat, size=0.7)
    bpy.ops.object.shade_smooth()
    add_camera(location=(0, -5.5, 2.2), rotation=(math.radians(76), 0, 0), lens=30)
    return scene


@pytest.mark.parametrize("interpolation", ["Linear", "Closest"])
def test_hdri_world_lights_and_shows_like_cycles(tmp_path, interpolation):
    _scene(tmp_path, interpolation=interpolation)
    cyc = render_cycles(bpy.context.scene, tmp_path, samples=SPP, seeds=(0, 1, 2))
    stpm, res = render_stpm(bpy.context.scene, samples=SPP, seeds=(0, 1, 2))
    r = block_ztest(stpm, cyc)
    print(f"hdri {interpolation}: {r.summary()}")
    assert not any("mean radiance" in w for w in res.warnings), res.warnings
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()


def test_animated_mapping_rotation_is_sampled_across_the_shutter(tmp_path):
    """A keyframed Mapping Z rotation (0 at frame 1, 90 degrees at frame 2, linear) with a one-frame
    shutter centred on frame 1.5: the world's map-to-world rotation moves across the shutter, each
    key the inverse of the node's rotation at that instant."""
    from test_addon_scenes import export_now, linear_keys
    scene = fresh()
    write_hdri(tmp_path / "sky.exr")
    world = hdri_world(tmp_path / "sky.exr", rotation_z=0.0)
    mp = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeMapping")
    rot = mp.inputs["Rotation"]
    rot.default_value = (0.0, 0.0, 0.0)
    rot.keyframe_insert("default_value", frame=1)
    rot.default_value = (0.0, 0.0, math.radians(90.0))
    rot.keyframe_insert("default_value", frame=2)
    linear_keys(world.node_tree)
    add_mesh("plane", "Floor")
    add_camera()
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 1.0
    scene.frame_set(1)
    scene.frame_current = 1
    core, warnings = export_now(motion_steps=3)
    tf = core.world.mapping
    assert not tf.is_static, warnings
    for u in (0.0, 0.5, 1.0):
        M = tf.at(np.array([u]))[0][:3, :3]
        frame = 1.0 + (u - 0.5) if scene.render.motion_blur_position == "CENTER" else 1.0 + u
        a = math.radians(90.0) * np.clip(frame - 1.0, 0.0, 1.0)
        Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
        np.testing.assert_allclose(M, Rz.T, atol=1e-5)
