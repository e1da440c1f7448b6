"""Direct light only on review/out/interior.blend, one kind of light at a time, STPM against Cycles.

PYTHONPATH=. python review/direct_light_probe.py VARIANT [SPP]
VARIANT: all | world (lamp shade and TV emission 0) | shade (world 0, TV 0) | tv (world 0, shade 0);
--diffuse-wall: the walls a Diffuse BSDF; --metallic-wall: the walls' Specular IOR Level 0.
Cycles: max_bounces 0 (NEE + the BSDF ray's hit of an emitter, MIS, as Cycles' direct light);
STPM: no photons, Diffuse / Glossy / Transmission bounces 0 (its Combined is then direct light).
160 x 90.  Prints the ratio STPM / Cycles of the upper wall (rows 0-30 %), the floor (rows 60-100 %)
and the image."""
import sys, time, tempfile
from pathlib import Path
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent)); sys.path.insert(0, str(HERE.parent / "tests"))
import numpy as np
import bpy, addon
addon.register()
from cycles_ref import render_cycles, render_stpm

variant = sys.argv[1]; spp = int(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[2].isdigit() else 64
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
s = bpy.context.scene; s.frame_set(12)
s.render.resolution_x, s.render.resolution_y = 160, 90
s.render.use_motion_blur = False
if variant in ("shade", "tv"):
    s.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
if variant in ("world", "tv"):
    bpy.data.materials["LampShade"].node_tree.nodes["Emission"].inputs["Strength"].default_value = 0.0
if variant in ("world", "shade"):
    bpy.data.materials["TVScreen"].node_tree.nodes["Emission"].inputs["Strength"].default_value = 0.0
if "--diffuse-wall" in sys.argv:      # the walls' Principled (roughness 0.9) replaced by a Diffuse BSDF
    nt = bpy.data.materials["Wall"].node_tree; b = nt.nodes["Principled BSDF"]
    d = nt.nodes.new("ShaderNodeBsdfDiffuse"); d.inputs["Color"].default_value = b.inputs["Base Color"].default_value
    nt.links.new(d.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    variant += "+diffuse-wall"
if "--metallic-wall" in sys.argv:     # the walls' Principled with Specular IOR Level 0 (no specular layer)
    bpy.data.materials["Wall"].node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    variant += "+no-specular-wall"
tmp = Path(tempfile.mkdtemp())
t = time.time(); cyc = render_cycles(s, tmp, samples=spp, seeds=(0, 1), max_bounces=0).mean(0); tc = time.time() - t
s.render.engine = "STPM"
t = time.time()
from addon.batch import render_visibility
with render_visibility(bpy.context.view_layer):     # what F12 renders: the hidden Boolean cutter left out
    st, _ = render_stpm(s, samples=spp, seeds=(0, 1), photons_global=0, photons_caustic=0, diffuse_bounces=0,
                        glossy_bounces=0, transmission_bounces=0)
st = st.mean(0); ts = time.time() - t
H = st.shape[0]
for name, sl in (("wall", slice(0, int(0.3 * H))), ("floor", slice(int(0.6 * H), H)), ("image", slice(0, H))):
    print(f"{variant}: {name} STPM/Cycles {st[sl].mean() / cyc[sl].mean():.4f} (Cycles {cyc[sl].mean():.5f})")
print(f"times: Cycles {tc:.1f} s, STPM {ts:.1f} s")
np.save(tmp / "cyc.npy", cyc); np.save(tmp / "stpm.npy", st); print("arrays in", tmp)
B = 10; Hh, Ww = cyc.shape[:2]; h, w = Hh // B, Ww // B
blk = lambda x: x[:h * B, :w * B].mean(-1).reshape(h, B, w, B).mean((1, 3))
np.set_printoptions(precision=2, linewidth=220, suppress=True)
print("10x10-block ratios STPM / Cycles:"); print(blk(st) / np.maximum(blk(cyc), 1e-9))
