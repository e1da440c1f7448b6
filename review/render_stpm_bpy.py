"""Render a .blend with engine STPM through bpy (as F12 / blender -b -E STPM): python render_stpm_bpy.py FILE SAMPLES [FRAME]"""
import sys, time
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import bpy, addon
addon.register()
f, spp = sys.argv[1], int(sys.argv[2]); frame = int(sys.argv[3]) if len(sys.argv) > 3 else None
bpy.ops.wm.open_mainfile(filepath=f)
s = bpy.context.scene
if frame is not None: s.frame_set(frame)
s.render.engine = "STPM"; s.stpm.samples = spp
out = Path(f).with_name(Path(f).stem + f"_stpmbpy{spp}")
from addon.batch import _set_format; _set_format(s.render.image_settings, "EXR"); s.render.filepath = str(out) + ".exr"; s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); print("stpm time", time.time() - t)
