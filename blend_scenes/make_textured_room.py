"""Build ``textured_room.blend``: a room built the way an artist builds one (issue 13's scene).

* a 4 x 4 x 2.6 m room; the floor is an 8-bit sRGB wood-plank image (``textures/planks.png``,
  written next to the .blend, repeated 3 x through a Mapping node on the plane's UVs) with a
  tangent-space normal map (``textures/planks_normal.png``, Non-Color) for the plank seams;
* the back wall a Checker texture through Object coordinates mixed (Multiply) with a Gradient
  through a ColorRamp; the side walls plain paint;
* a table (a box, UV-unwrapped with Smart UV Project) with a 16-bit tile image
  (``textures/tiles16.png``, Closest interpolation) and a Hue/Saturation tweak;
* a glass sphere on the table and a rough-metal cylinder;
* a sun lamp shining through a window opening in the left wall (the wall is a mesh with a hole);
* a camera dollying sideways 0.3 m per frame (0.15 m during the 0.5-frame shutter).

    .venv/bin/python blend_scenes/make_textured_room.py [OUT.blend]

The images are generated here with numpy (no downloads) and saved as files, loaded by
``bpy.data.images.load`` as an artist's files would be.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import bpy
from _common import add_box, add_plane, add_sphere, camera, finish, keyframes, mesh_object, new_scene, out_path


def _save_png(path: Path, rgb: np.ndarray, bits: int = 8) -> None:
    """Write (h, w, 3) values in [0, 1] (row 0 = top) with OpenImageIO."""
    import OpenImageIO as oiio
    h, w, c = rgb.shape
    spec = oiio.ImageSpec(w, h, c, "uint8" if bits == 8 else "uint16")
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    top = 255.0 if bits == 8 else 65535.0
    out.write_image(np.round(np.clip(rgb, 0, 1) * top).astype(np.uint8 if bits == 8 else np.uint16))
    out.close()


def make_images(folder: Path) -> dict:
    """planks.png (512 x 512 sRGB), planks_normal.png (512 x 512, Non-Color), tiles16.png (64 x 64,
    16-bit): returns {name: path}."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(42)
    n = 512
    y, x = np.mgrid[0:n, 0:n] / n
    plank = np.floor(y * 6)                                   # 6 planks across
    shade = rng.uniform(0.75, 1.1, 6)[plank.astype(int)]
    grain = 0.08 * np.sin(60 * x + 8 * np.sin(7 * y + plank)) + 0.05 * rng.standard_normal((n, n))
    base = np.stack([0.55, 0.36, 0.2]) * (shade + grain)[..., None]
    seam = np.abs(y * 6 - np.round(y * 6)) < 0.02
    base[seam] *= 0.35
    paths = {"planks": folder / "planks.png", "normal": folder / "planks_normal.png",
             "tiles": folder / "tiles16.png"}
    _save_png(paths["planks"], base)
    # Normal map: the seams are grooves (height dips), tangent space
    hgt = -np.exp(-((y * 6 - np.round(y * 6)) / 0.03) ** 2)
    dy = np.gradient(hgt, axis=0) * n / 40.0
    dx = np.gradient(hgt, axis=1) * n / 40.0
    nrm = np.stack([-dx, dy, np.ones_like(hgt)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    _save_png(paths["normal"], 0.5 * nrm + 0.5)
    t = 64
    ty, tx = np.mgrid[0:t, 0:t]
    checker = ((tx // 8 + ty // 8) % 2).astype(float)
    tiles = np.stack([0.2 + 0.6 * checker, 0.3 + 0.3 * checker, 0.5 - 0.2 * checker], -1)
    _save_png(paths["tiles"], tiles, bits=16)
    return paths


def _tree(mat):
    t = mat.node_tree
    for node in list(t.nodes):
        if node.bl_idname != "ShaderNodeOutputMaterial":
            t.nodes.remove(node)
    return t, next(node for node in t.nodes if node.bl_idname == "ShaderNodeOutputMaterial")


def floor_material(paths) -> "bpy.types.Material":
    mat = bpy.data.materials.new("Planks")
    t, out = _tree(mat)
    bsdf = t.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 0.6
    coord, mapping = t.nodes.new("ShaderNodeTexCoord"), t.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (3.0, 3.0, 1.0)
    t.links.new(coord.outputs["UV"], mapping.inputs["Vector"])
    col = t.nodes.new("ShaderNodeTexImage")
    col.image = bpy.data.images.load(str(paths["planks"]))
    t.links.new(mapping.outputs["Vector"], col.inputs["Vector"])
    t.links.new(col.outputs["Color"], bsdf.inputs["Base Color"])
    nrm_tex = t.nodes.new("ShaderNodeTexImage")
    nrm_tex.image = bpy.data.images.load(str(paths["normal"]))
    nrm_tex.image.colorspace_settings.name = "Non-Color"
    t.links.new(mapping.outputs["Vector"], nrm_tex.inputs["Vector"])
    nmap = t.nodes.new("ShaderNodeNormalMap")
    t.links.new(nrm_tex.outputs["Color"], nmap.inputs["Color"])
    t.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def wall_material() -> "bpy.types.Material":
    mat = bpy.data.materials.new("Wallpaper")
    t, out = _tree(mat)
    bsdf = t.nodes.new("ShaderNodeBsdfDiffuse")
    coord = t.nodes.new("ShaderNodeTexCoord")
    checker = t.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (0.8, 0.75, 0.6, 1)
    checker.inputs["Color2"].default_value = (0.55, 0.6, 0.7, 1)
    t.links.new(coord.outputs["Object"], checker.inputs["Vector"])
    grad = t.nodes.new("ShaderNodeTexGradient")
    t.links.new(coord.outputs["Generated"], grad.inputs["Vector"])
    ramp = t.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.7, 0.7, 0.7, 1)
    ramp.color_ramp.elements[1].color = (1.0, 1.0, 1.0, 1)
    t.links.new(grad.outputs["Fac"], ramp.inputs["Fac"])
    mix = t.nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
    mix.inputs["Factor"].default_value = 1.0
    t.links.new(checker.outputs["Color"], mix.inputs[6])
    t.links.new(ramp.outputs["Color"], mix.inputs[7])
    t.links.new(mix.outputs[2], bsdf.inputs["Color"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def table_material(paths) -> "bpy.types.Material":
    mat = bpy.data.materials.new("Tiles")
    t, out = _tree(mat)
    bsdf = t.nodes.new("ShaderNodeBsdfPrincipled")
    tex = t.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(paths["tiles"]))
    tex.interpolation = "Closest"
    hsv = t.nodes.new("ShaderNodeHueSaturation")
    hsv.inputs["Saturation"].default_value = 1.3
    t.links.new(tex.outputs["Color"], hsv.inputs["Color"])
    t.links.new(hsv.outputs["Color"], bsdf.inputs["Base Color"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def simple(name, node, **inputs):
    mat = bpy.data.materials.new(name)
    t, out = _tree(mat)
    s = t.nodes.new(node)
    for k, v in inputs.items():
        s.inputs[k].default_value = v
    t.links.new(s.outputs[0], out.inputs["Surface"])
    return mat


def smart_uv(obj) -> None:
    bpy.context.view_layer.objects.active = obj
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project()
    bpy.ops.object.mode_set(mode="OBJECT")


def wall_with_window(name: str, mat):
    """The left wall (x = -2), 4 m wide, 2.6 m high, a 1.2 x 1.0 m window opening."""
    ys, zs = (-2.0, -0.6, 0.6, 2.0), (0.0, 0.9, 1.9, 2.6)
    verts = [(0.0, y, z) for z in zs for y in ys]
    faces = []
    for j in range(3):
        for i in range(3):
            if (i, j) == (1, 1):
                continue                                     # the window
            a = j * 4 + i
            faces.append((a, a + 4, a + 5, a + 1))
    return mesh_object(name, verts, faces, mat, location=(-2.0, 0.0, 0.0))


def build(path: Path) -> Path:
    scene = new_scene("TexturedRoom")
    paths = make_images(path.parent / "textures")
    floor = add_plane("Floor", 4.0, floor_material(paths), location=(0, 0, 0))
    add_plane("Back", 4.0, wall_material(), location=(0, 2, 1.3), rotation=(math.pi / 2, 0, 0)).scale[1] = 0.65
    paint = simple("Paint", "ShaderNodeBsdfDiffuse", Color=(0.7, 0.68, 0.62, 1))
    add_plane("Right", 4.0, paint, location=(2, 0, 1.3), rotation=(0, -math.pi / 2, 0)).scale[0] = 0.65
    add_plane("Ceiling", 4.0, paint, location=(0, 0, 2.6), rotation=(math.pi, 0, 0))
    wall_with_window("LeftWall", paint)
    table = add_box("Table", 1.0, table_material(paths), location=(0.3, 0.5, 0.35))
    table.scale = (0.9, 0.6, 0.35)
    smart_uv(table)
    add_sphere("GlassBall", 0.18, simple("Glass", "ShaderNodeBsdfGlass", IOR=1.45, Roughness=0.0),
               location=(0.1, 0.4, 0.88))
    bpy.ops.mesh.primitive_cylinder_add(radius=0.12, depth=0.4, location=(0.6, 0.6, 0.9))
    cyl = bpy.context.object
    cyl.name = "Copper"
    cyl.data.materials.append(simple("Copper", "ShaderNodeBsdfPrincipled", Metallic=1.0, Roughness=0.35,
                                     **{"Base Color": (0.95, 0.6, 0.45, 1)}))
    del floor
    sun = bpy.data.lights.new("Sun", type="SUN")
    sun.energy, sun.angle = 4.0, math.radians(1.0)
    sun_obj = bpy.data.objects.new("Sun", sun)
    sun_obj.rotation_euler = (math.radians(55), 0.0, math.radians(-70))   # from the left, through the window
    scene.collection.objects.link(sun_obj)
    cam = camera((0.4, -3.4, 1.4), (80.0, 0.0, 0.0), lens=26.0)
    keyframes(cam, "location", [(0, (0.1, -3.4, 1.4)), (2, (0.7, -3.4, 1.4))])   # 0.3 m per frame
    out = finish(scene, path, resolution=(320, 240), world=(0.02, 0.025, 0.03))
    bpy.ops.file.make_paths_relative()                 # the textures travel with the .blend
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    return out


if __name__ == "__main__":
    print(build(out_path("textured_room.blend")))
