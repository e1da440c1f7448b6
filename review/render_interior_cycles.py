"""Cycles on review/out/interior.blend, frame 12: python review/render_interior_cycles.py SPP [TAG] [--time-limit S]
CPU, no denoising, no adaptive sampling, clamps off (Cycles' unbiased answer; the tests' settings). Max bounces
left at the file's (Cycles' defaults: 12 total, diffuse 4, glossy 4, transmission 12). Writes
review/out/interior_cycles_<TAG>.exr and prints the wall time."""
import sys, time
import bpy
from _review_common import HERE, unbiased_cycles
args = sys.argv[1:]; spp = int(args[0]); tag = args[1] if len(args) > 1 and not args[1].startswith("--") else str(spp)
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
s = bpy.context.scene; s.frame_set(12)
cy = unbiased_cycles(s, spp)
cy.seed = int(args[args.index("--seed") + 1]) if "--seed" in args else 0
if "--time-limit" in args:
    cy.time_limit = float(args[args.index("--time-limit") + 1])
s.render.image_settings.media_type = "IMAGE"; s.render.image_settings.file_format = "OPEN_EXR"
s.render.image_settings.color_depth = "32"
s.render.filepath = str(HERE / "out" / f"interior_cycles_{tag}.exr"); s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); print(f"cycles {spp} spp wall {time.time() - t:.1f} s")
