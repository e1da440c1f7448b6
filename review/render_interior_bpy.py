"""The artist's F12 on review/out/interior.blend, through bpy with the add-on as the tests enable it.

python review/render_interior_bpy.py PRESET [SAMPLES] [--denoise] [--bake] [--tag T]
Applies the preset (bpy.ops.stpm.apply_preset), optionally overrides samples, ticks the view layer's
Mist and Denoising Data passes (as a Cycles user would have them), Denoise if asked, bakes the
unsupported inputs (the Sky) if asked, renders frame 12 with write_still (multilayer EXR) and prints
the render report's warnings, the stats' phases and the passes written.
Writes review/out/interior_<tag>.exr (compare_flip.py / ratio_map.py make PNGs of it).
"""
import sys
import time

import bpy

from _review_common import OUT, open_for_f12, print_f12_report

args = sys.argv[1:]
preset = args[0]
samples = int(args[1]) if len(args) > 1 and args[1].isdigit() else None
tag = args[args.index("--tag") + 1] if "--tag" in args else preset.lower()
s = open_for_f12(OUT / "interior.blend", preset, samples)
vl = s.view_layers[0]
vl.use_pass_mist = True
vl.cycles.denoising_store_passes = True
s.stpm.denoise = "--denoise" in args
if "--bake" in args:
    t = time.time(); print("bake:", bpy.ops.stpm.bake_inputs(), f"{time.time() - t:.1f} s")
s.frame_set(12)
out = OUT / f"interior_{tag}"
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
s.render.image_settings.color_depth = "32"
s.render.filepath = str(out) + ".exr"; s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); wall = time.time() - t
print_f12_report(wall)
