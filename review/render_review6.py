"""The artist's renders of review/out/watch6*.blend (review/make_review6.py), through bpy.

python review/render_review6.py FILE MODE [PRESET] [--samples S] [--tag T] [--exr] [--seed S] [--size WxH]
                                [--no-denoise] [--passes-out]
FILE:  watch6, watch6_sky or watch6_alpha (review/out/FILE.blend)
MODE f12:    the Render panel path: preset (bpy.ops.stpm.apply_preset), then bpy.ops.render.render
             (write_still) on frame 2; prints the render report's warnings and stats.
MODE cycles: Cycles at matched settings (CPU, no denoising, no adaptive sampling, clamps off, Filter
             Glossy 0).
--exr writes a multilayer float EXR (every pass) instead of the file's PNG.
Outputs go to review/out/FILE_<mode>_<tag>.*.
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
name, mode = args[0], args[1]
preset = args[2] if len(args) > 2 and not args[2].startswith("--") else None


def opt(key, cast=str, default=None):
    return cast(args[args.index(key) + 1]) if key in args else default


tag = opt("--tag", default=(preset or "file").lower())
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / f"{name}.blend"))
s = bpy.context.scene
r = s.render
if "--size" in args:
    r.resolution_x, r.resolution_y = map(int, opt("--size").split("x"))
if mode == "cycles":
    r.engine = "CYCLES"; cy = s.cycles
    cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", opt("--samples", int, 512), False, False
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    cy.seed = opt("--seed", int, 0)
else:
    r.engine = "STPM"
    if preset:
        bpy.ops.stpm.apply_preset(preset=preset)
    if "--samples" in args:
        s.stpm.samples = opt("--samples", int)
    if "--seed" in args:
        s.stpm.seed = opt("--seed", int)
    if "--no-denoise" in args:
        s.stpm.denoise = False
if "--passes-out" in args:
    # the compositor's File Output node writes STPM's passes beside the image (as an artist's comp does)
    from addon.denoise import scene_compositor
    tree = scene_compositor(s)
    rl = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers")
    fo = tree.nodes.new("CompositorNodeOutputFile")
    fo.directory = str(HERE / "out" / f"{name}_passes"); fo.file_name = "pass_"
    fo.file_output_items.clear()
    for p in ("Direct", "Indirect", "Caustic", "Emit", "Depth"):
        fo.file_output_items.new("FLOAT" if p == "Depth" else "RGBA", p)
        tree.links.new(rl.outputs[p], fo.inputs[p])
if "--exr" in args:
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"; r.image_settings.color_depth = "32"
from addon.engine import LAST_RENDER  # noqa: E402
t = time.time()
s.frame_set(2)
ext = ".exr" if "--exr" in args else r.file_extension
r.filepath = str(HERE / "out" / f"{name}_{mode}_{tag}{ext}"); r.use_file_extension = False
bpy.ops.render.render(write_still=True)
wall = time.time() - t
print(f"{mode} wall {wall:.1f} s -> {r.filepath}")
if mode != "cycles":
    for w in LAST_RENDER.get("warnings", []):
        print("WARNING:", w)
    st = LAST_RENDER.get("stats", {})
    print(json.dumps({k: st.get(k) for k in ("export_s", "photon_trace_s", "photon_map_build_s", "render_s",
                                             "photons_global", "photons_caustic", "samples", "resolution")}))
