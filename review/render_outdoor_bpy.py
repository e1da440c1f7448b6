"""The artist's F12 on review/out/outdoor.blend, through bpy with the add-on enabled as the tests do.

python review/render_outdoor_bpy.py PRESET [SAMPLES] [--bake] [--tag T] [--file outdoor_bad] [--anim A-B]
Applies the preset (bpy.ops.stpm.apply_preset), optionally overrides samples, ticks the view
layer's Mist, Diffuse Direct and Shadow Catcher passes (as a Cycles user would have them), bakes
the unsupported inputs (the Sky) if asked, renders frame 10 with write_still (multilayer EXR), or
the frame range A-B as an animation, and prints the render report's warnings and the stats.
Writes review/out/<file>_<tag>.exr.
"""
import sys
import time

import bpy

from _review_common import OUT, open_for_f12, print_f12_report

args = sys.argv[1:]
preset = args[0]
samples = int(args[1]) if len(args) > 1 and args[1].isdigit() else None
tag = args[args.index("--tag") + 1] if "--tag" in args else preset.lower()
name = args[args.index("--file") + 1] if "--file" in args else "outdoor"
s = open_for_f12(OUT / f"{name}.blend", preset, samples)
vl = s.view_layers[0]
vl.use_pass_mist = True
vl.use_pass_diffuse_direct = True
vl.cycles.use_pass_shadow_catcher = True
if "--bake" in args:
    t = time.time(); print("bake:", bpy.ops.stpm.bake_inputs(), f"{time.time() - t:.1f} s")
s.frame_set(10)
out = OUT / f"{name}_{tag}"
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
s.render.image_settings.color_depth = "32"
t = time.time()
if "--anim" in args:
    a, b = map(int, args[args.index("--anim") + 1].split("-"))
    s.frame_start, s.frame_end = a, b
    s.render.filepath = str(out) + "_####"
    s.render.use_file_extension = True
    bpy.ops.render.render(animation=True)
else:
    s.render.filepath = str(out) + ".exr"; s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
wall = time.time() - t
print_f12_report(wall, errors=True)
