"""F12 through bpy with a preset: python render_bottle_bpy.py FILE PRESET [OUT_STEM] [key=value ...]

PRESET: PREVIEW, FINAL, PREVIEW_PROGRESSIVE, FINAL_PROGRESSIVE or NONE (the file's settings);
key=value sets scene.stpm.<key> (ints/floats parsed).  Prints the time, warnings, stats summary and
writes OUT_STEM.exr (multilayer) and OUT_STEM.png (the view transform applied, as F12 saves)."""
import sys, time
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import bpy, addon
from addon.engine import LAST_RENDER
from addon.batch import _set_format
addon.register()
f, preset = sys.argv[1], sys.argv[2]
stem = sys.argv[3] if len(sys.argv) > 3 and "=" not in sys.argv[3] else str(Path(f).with_name(Path(f).stem + "_stpm_" + preset.lower()))
bpy.ops.wm.open_mainfile(filepath=f)
s = bpy.context.scene; s.render.engine = "STPM"
if preset != "NONE": bpy.ops.stpm.apply_preset(preset=preset)
for kv in sys.argv[3:]:
    if "=" in kv:
        k, v = kv.split("=", 1)
        cur = getattr(s.stpm, k)
        setattr(s.stpm, k, type(cur)(v) if not isinstance(cur, bool) else v.lower() in ("1", "true", "on"))
_set_format(s.render.image_settings, "EXR"); s.render.filepath = stem + ".exr"; s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); dt = time.time() - t
print(f"STPM {preset} time {dt:.1f} s")
for w in LAST_RENDER.get("warnings", []): print("  WARNING:", w)
st = LAST_RENDER.get("stats", {})
print("  stats:", {k: st.get(k) for k in ("wall_s", "photon_trace_s", "render_s", "photons_global", "photons_caustic", "samples", "resolution")})
import json; Path(stem + "_stats.json").write_text(json.dumps(st, indent=1, default=str))
_set_format(s.render.image_settings, "PNG")
bpy.data.images["Render Result"].save_render(stem + ".png")
