"""The artist's renders of review/out/kitchen5.blend (review/make_interior5.py), through bpy.

python review/render_kitchen5.py MODE [PRESET] [--samples S] [--tag T] [--exr] [--time-limit S] [--seed S]
MODE f12:   the Render panel path: preset (bpy.ops.stpm.apply_preset), then bpy.ops.render.render
            (write_still) on frame 2; prints the render report's warnings, info lines and stats.
MODE batch: what `blender -b kitchen5.blend -E STPM -f 2` does: the file as saved, engine set to STPM,
            one frame (2) rendered as an animation of one frame, written to the file's output path
            (render.filepath + frame number, the file's format).
MODE cycles: Cycles at matched settings (CPU, no denoising, no adaptive sampling, clamps off, Filter Glossy 0:
            the file's 1.0 made Cycles 5.3 % dark with the counter's light alone, docs/blender.md).
--exr writes a multilayer float EXR instead of the file's format (for comparisons).
Outputs go to review/out/kitchen5_<mode>_<tag>.* (batch: the file's render.filepath).
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
mode = args[0]
preset = args[1] if len(args) > 1 and not args[1].startswith("--") else None


def opt(name, cast=str, default=None):
    return cast(args[args.index(name) + 1]) if name in args else default


tag = opt("--tag", default=(preset or "file").lower())
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "kitchen5.blend"))
s = bpy.context.scene
r = s.render
if opt("--border") == "off":
    r.use_border = False
if mode == "cycles":
    r.engine = "CYCLES"; cy = s.cycles
    cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", opt("--samples", int, 256), False, False
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    cy.seed = opt("--seed", int, 0)
    if "--time-limit" in args:
        cy.time_limit = opt("--time-limit", float)
else:
    r.engine = "STPM"
    if preset:
        bpy.ops.stpm.apply_preset(preset=preset)
    if "--samples" in args:
        s.stpm.samples = opt("--samples", int)
    if "--seed" in args:
        s.stpm.seed = opt("--seed", int)
if "--exr" in args:
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"; r.image_settings.color_depth = "32"
from addon.engine import LAST_RENDER  # noqa: E402
t = time.time()
if mode == "batch":
    s.frame_start = s.frame_end = 2
    if "--out" in args:
        r.filepath = opt("--out")
    bpy.ops.render.render(animation=True)
else:
    s.frame_set(2)
    ext = ".exr" if "--exr" in args else r.file_extension
    r.filepath = str(HERE / "out" / f"kitchen5_{mode}_{tag}{ext}"); r.use_file_extension = False
    bpy.ops.render.render(write_still=True)
wall = time.time() - t
print(f"{mode} wall {wall:.1f} s -> {r.filepath}")
if mode != "cycles":
    for w in LAST_RENDER.get("warnings", []):
        print("WARNING:", w)
    for k in ("errors", "info"):
        for e in LAST_RENDER.get(k, []) if isinstance(LAST_RENDER.get(k), list) else []:
            print(k.upper(), e)
    st = LAST_RENDER.get("stats", {})
    print(json.dumps({k: st.get(k) for k in ("export_s", "photon_trace_s", "photon_map_build_s", "render_s",
                                             "photons_global", "photons_caustic", "samples", "resolution")}))
res = bpy.data.images.get("Render Result")
if res:
    print("render result size", tuple(res.size))
