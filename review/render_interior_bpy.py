"""The artist's F12 on review/out/interior.blend, through bpy with the add-on as the tests enable it.

python review/render_interior_bpy.py PRESET [SAMPLES] [--denoise] [--bake] [--tag T]
Applies the preset (bpy.ops.stpm.apply_preset), optionally overrides samples, ticks the view layer's
Mist and Denoising Data passes (as a Cycles user would have them), Denoise if asked, bakes the
unsupported inputs (the Sky) if asked, renders frame 12 with write_still (multilayer EXR) and prints
the render report's warnings, the stats' phases and the passes written.
Writes review/out/interior_<tag>.exr (compare_flip.py / ratio_map.py make PNGs of it).
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
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
s = bpy.context.scene
s.render.engine = "STPM"
bpy.ops.stpm.apply_preset(preset=preset)
if samples:
    s.stpm.samples = samples
vl = s.view_layers[0]
vl.use_pass_mist = True
vl.cycles.denoising_store_passes = True
s.stpm.denoise = "--denoise" in args
if "--bake" in args:
    t = time.time(); print("bake:", bpy.ops.stpm.bake_inputs(), f"{time.time() - t:.1f} s")
s.frame_set(12)
out = HERE / "out" / f"interior_{tag}"
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
s.render.image_settings.color_depth = "32"
s.render.filepath = str(out) + ".exr"; s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); wall = time.time() - t
from addon.engine import LAST_RENDER  # noqa: E402
st = LAST_RENDER.get("stats", {})
print(f"F12 wall {wall:.1f} s")
for w in LAST_RENDER.get("warnings", []):
    print("WARNING:", w)
print("passes:", LAST_RENDER.get("passes"))
print(json.dumps({k: st.get(k) for k in ("export_s", "photon_trace_s", "photon_map_build_s", "render_s", "render_wall_s",
                                         "photons_global", "photons_caustic", "samples")}))
