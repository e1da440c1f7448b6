"""Render a .blend with Cycles at given spp to out/<stem>_cycles.exr/.png: python render_cycles.py FILE SPP [FRAME]"""
import sys, time, bpy
from pathlib import Path
f, spp = sys.argv[1], int(sys.argv[2]); frame = int(sys.argv[3]) if len(sys.argv) > 3 else None
bpy.ops.wm.open_mainfile(filepath=f)
s = bpy.context.scene
if frame is not None: s.frame_set(frame)
s.render.engine = "CYCLES"; s.cycles.samples = spp; s.cycles.use_denoising = False; s.cycles.device = "CPU"
s.cycles.use_adaptive_sampling = False; s.render.threads_mode = "FIXED"; s.render.threads = 1
out = Path(f).with_name(Path(f).stem + f"_cycles{spp}")
s.render.image_settings.file_format = "OPEN_EXR"; s.render.filepath = str(out) + ".exr"; s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); print("cycles time", time.time() - t)
s.render.image_settings.file_format = "PNG"; s.render.filepath = str(out) + ".png"
bpy.data.images["Render Result"].save_render(str(out) + ".png")
