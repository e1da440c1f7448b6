"""The artist's F12 on review/out/outdoor.blend, through bpy with the add-on enabled as the tests do.

python review/render_outdoor_bpy.py PRESET [SAMPLES] [--bake] [--tag T] [--file outdoor_bad] [--anim A-B]
Applies the preset (bpy.ops.stpm.apply_preset), optionally overrides samples, ticks the view
layer's Mist, Diffuse Direct and Shadow Catcher passes (as a Cycles user would have them), bakes
the unsupported inputs (the Sky) if asked, renders frame 10 with write_still (multilayer EXR), or
the frame range A-B as an animation, and prints the render report's warnings and the stats.
Writes review/out/<file>_<tag>.exr.
"""
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import bpy  # noqa: E402
import addon  # noqa: E402

addon.register()
args = sys.argv[1:]
preset = args[0]
samples = int(args[1]) if len(args) > 1 and args[1].isdigit() else None
tag = args[args.index("--tag") + 1] if "--tag" in args else preset.lower()
name = args[args.index("--file") + 1] if "--file" in args else "outdoor"
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / f"{name}.blend"))
s = bpy.context.scene
s.render.engine = "STPM"
bpy.ops.stpm.apply_preset(preset=preset)
if samples:
    s.stpm.samples = samples
vl = s.view_layers[0]
vl.use_pass_mist = True
vl.use_pass_diffuse_direct = True
vl.cycles.use_pass_shadow_catcher = True
if "--bake" in args:
    t = time.time(); print("bake:", bpy.ops.stpm.bake_inputs(), f"{time.time() - t:.1f} s")
s.frame_set(10)
out = HERE / "out" / f"{name}_{tag}"
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
s.render.image_settings.color_depth = "32"
from addon.engine import LAST_RENDER  # noqa: E402
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
st = LAST_RENDER.get("stats", {})
print(f"F12 wall {wall:.1f} s")
for w in LAST_RENDER.get("warnings", []):
    print("WARNING:", w)
for e in LAST_RENDER.get("errors", []) if isinstance(LAST_RENDER.get("errors"), list) else []:
    print("ERROR:", e)
print("LAST_RENDER keys:", sorted(LAST_RENDER))
print("passes:", LAST_RENDER.get("passes"))
print(json.dumps({k: st.get(k) for k in ("export_s", "photon_trace_s", "photon_map_build_s", "render_s", "render_wall_s",
                                         "photons_global", "photons_caustic", "samples")}))
