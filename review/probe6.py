"""Probes of review/out/watch6.blend (artist review 6): one renderer, objects hidden or settings changed,
the mean of a crop printed.

python review/probe6.py stpm|cycles OUT.exr [--samples S] [--size WxH] [--hide A,B] [--set key=val,...]
                        [--crop x0,y0,x1,y1] [--file watch6] [--scale-xy Name=f,...] [--aniso0]
--set sets scene.stpm fields (stpm) or scene.cycles fields (cycles); --crop is in pixels, rows from the top.
"""
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import bpy  # noqa: E402
import addon  # noqa: E402

addon.register()
args = sys.argv[1:]
engine, out = args[0], args[1]


def opt(key, default=None):
    return args[args.index(key) + 1] if key in args else default


bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / f"{opt('--file', 'watch6')}.blend"))
s = bpy.context.scene
r = s.render
r.resolution_x, r.resolution_y = map(int, opt("--size", "160x90").split("x"))
for name in filter(None, opt("--hide", "").split(",")):
    bpy.data.objects[name].hide_render = True
for kv in filter(None, opt("--scale-xy", "").split(",")):         # Name=f: scale an object in x and y
    k, v = kv.split("=")
    bpy.data.objects[k].scale.x = bpy.data.objects[k].scale.y = float(v)
if "--aniso0" in args:                                              # every Principled Anisotropic to 0
    for m in bpy.data.materials:
        for n in (m.node_tree.nodes if m.node_tree else []):
            if n.bl_idname == "ShaderNodeBsdfPrincipled":
                n.inputs["Anisotropic"].default_value = 0.0
s.stpm.denoise = False
if engine == "cycles":
    r.engine = "CYCLES"; cy = s.cycles
    cy.device, cy.use_denoising, cy.use_adaptive_sampling = "CPU", False, False
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    cy.samples = int(opt("--samples", 256))
    target = cy
else:
    r.engine = "STPM"
    bpy.ops.stpm.apply_preset(preset="FINAL")
    s.stpm.use_adaptive_sampling = False
    s.stpm.samples = int(opt("--samples", 64))
    target = s.stpm
for kv in filter(None, opt("--set", "").split(",")):
    k, v = kv.split("=")
    cur = getattr(target, k)
    setattr(target, k, type(cur)(float(v)) if not isinstance(cur, str) else v)
r.image_settings.media_type = "MULTI_LAYER_IMAGE"; r.image_settings.color_depth = "32"
s.frame_set(2)
r.filepath = out; r.use_file_extension = False
t = time.time()
bpy.ops.render.render(write_still=True)
print(f"{engine} wall {time.time() - t:.1f} s -> {out}")
import OpenImageIO as oiio  # noqa: E402
b = oiio.ImageBuf(out); names = list(b.spec().channelnames); px = b.get_pixels(oiio.FLOAT)
rgb = px[..., :3]                                      # the first part: Composite (no compositor: Combined)
print("image mean", rgb.mean(axis=(0, 1)))
if "--crop" in args:
    x0, y0, x1, y1 = map(int, opt("--crop").split(","))
    print("crop mean", rgb[y0:y1, x0:x1].mean(axis=(0, 1)))
