"""Cycles reference for the bottle scenes: python render_cycles_bottle.py FILE SPP [nodof] [nolightnodes] [noies] [threads=N]

Clamp Indirect 0, Filter Glossy 0 (docs/blender.md "Comparing with Cycles yourself"), no denoising,
no adaptive sampling.  Writes FILE_cyclesSPP[_nodof].exr (+ .png with the file's view transform)."""
import sys, time, bpy
from pathlib import Path
f, spp = sys.argv[1], int(sys.argv[2]); nodof = "nodof" in sys.argv
threads = int(next((a.split("=")[1] for a in sys.argv if a.startswith("threads=")), 1))
bpy.ops.wm.open_mainfile(filepath=f)
s = bpy.context.scene
s.render.engine = "CYCLES"; c = s.cycles
c.samples = spp; c.use_denoising = False; c.device = "CPU"; c.use_adaptive_sampling = False
c.sample_clamp_indirect = 0.0; c.blur_glossy = 0.0
s.render.threads_mode = "FIXED"; s.render.threads = threads
if nodof: s.camera.data.dof.use_dof = False
nolightnodes = "nolightnodes" in sys.argv      # what STPM renders: light node trees ignored (warned)
if nolightnodes:
    for l in bpy.data.lights: l.use_nodes = False
noies = "noies" in sys.argv                    # light node trees with an IES Texture off (STPM cannot read them)
if noies:
    for l in bpy.data.lights:
        if l.node_tree is not None and any(n.type == "TEX_IES" for n in l.node_tree.nodes): l.use_nodes = False
out = Path(f).with_name(Path(f).stem + f"_cycles{spp}" + ("_nodof" if nodof else "") + ("_nolightnodes" if nolightnodes else "") + ("_noies" if noies else ""))
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"; s.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
s.render.image_settings.color_depth = "32"
s.render.filepath = str(out) + ".exr"; s.render.use_file_extension = False
t = time.time(); bpy.ops.render.render(write_still=True); print(f"cycles {spp} time {time.time() - t:.1f} s")
s.render.image_settings.media_type = "IMAGE"; s.render.image_settings.file_format = "PNG"
bpy.data.images["Render Result"].save_render(str(out) + ".png")
