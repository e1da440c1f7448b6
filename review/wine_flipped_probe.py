"""Minimal repro (artist review 3): transmissive spheres with flipped (inward) normals, as the Screw
modifier made the interior's wine, STPM against Cycles (the flipped-normals test's stage and settings).

PYTHONPATH=.:tests python review/wine_flipped_probe.py [CASE ...]
Cases: principled_flipped / principled_outward (Principled, Transmission 1, IOR 1.33, red base colour),
glass_flipped (Glass BSDF, same colour and IOR).  Prints the block Z-test summary and the centre's means."""
import sys, tempfile
from pathlib import Path
import numpy as np
import bpy
from test_addon_scenes import add_mesh  # noqa: F401
from test_flipped_normals import _stage, _flip_all, DEPTH
from test_cycles_textures import _empty_material
from cycles_ref import block_ztest, render_cycles_paths, render_stpm

def sphere(make_mat, flip):
    _stage(); mat = make_mat()
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0, 0, 0), radius=1.0, segments=32, ring_count=16)
    obj = bpy.context.object; bpy.ops.object.shade_smooth(); obj.data.materials.append(mat)
    if flip:
        _flip_all(obj)

def principled():
    mat, t, out = _empty_material("Wine")
    b = t.nodes.new("ShaderNodeBsdfPrincipled")
    b.inputs["Base Color"].default_value = (0.5, 0.02, 0.05, 1); b.inputs["Roughness"].default_value = 0.0
    b.inputs["Transmission Weight"].default_value = 1.0; b.inputs["IOR"].default_value = 1.33
    t.links.new(b.outputs[0], out.inputs["Surface"]); return mat

def glass():
    mat, t, out = _empty_material("WineGlass")
    g = t.nodes.new("ShaderNodeBsdfGlass"); g.inputs["Color"].default_value = (0.5, 0.02, 0.05, 1)
    g.inputs["Roughness"].default_value = 0.0; g.inputs["IOR"].default_value = 1.33
    t.links.new(g.outputs[0], out.inputs["Surface"]); return mat

CASES = {"principled_flipped": lambda: sphere(principled, True), "principled_outward": lambda: sphere(principled, False),
         "glass_flipped": lambda: sphere(glass, True), "glass_outward": lambda: sphere(glass, False)}
for case in sys.argv[1:] or sorted(CASES):
    CASES[case]()
    scene = bpy.context.scene
    tmp = Path(tempfile.mkdtemp())
    cyc = render_cycles_paths(scene, tmp, samples=32, seeds=(0, 1), diffuse_bounces=0, glossy_bounces=DEPTH,
                              transmission_bounces=DEPTH, caustics=False)
    st, _ = render_stpm(scene, samples=32, seeds=(0, 1), max_depth=DEPTH, glossy_bounces=DEPTH, transmission_bounces=DEPTH)
    r = block_ztest(st, cyc)
    H, W = cyc.shape[1:3]
    c = lambda x: x.mean(0)[H // 2 - 6:H // 2 + 6, W // 2 - 6:W // 2 + 6].mean((0, 1)).round(4)
    print(f"{case}: {r.summary()}; centre RGB Cycles {c(cyc)} STPM {c(st)}", flush=True)
