"""The outdoor review's car paint (review/make_outdoor.py: Principled base (0.55, 0.02, 0.02), Metallic
0.7, a Noise texture at scale 600 through a ramp into Roughness and a Bump into Normal, Coat Weight 1,
Coat Roughness 0.03) on its ellipsoid blob, over a grey ground under a sun 30 degrees up and a pale
blue world, against Cycles: mean ratio over the blob's pixels (Cycles' Object Index pass) and
HDR-FLIP over the whole image and the blob's box.

PYTHONPATH=<checkout> python review/coat_layer_probe.py OUTDIR [STPM_SPP] [CYCLES_SPP] [COAT_WEIGHT]
The Cycles reference is cached in OUTDIR (cycles_<spp>_<coat>.npy, mask.npy); run it with another
checkout on PYTHONPATH to compare versions against the same reference.  COAT_WEIGHT (default 1)
0 measures the paint under the coat alone.
"""
import math
import sys
from pathlib import Path

import numpy as np
import bpy

from _review_common import car_body, car_paint, read_exr_layers, start_scene, unbiased_cycles

out = Path(sys.argv[1]); out.mkdir(parents=True, exist_ok=True)
stpm_spp = int(sys.argv[2]) if len(sys.argv) > 2 else 64
cyc_spp = int(sys.argv[3]) if len(sys.argv) > 3 else 512
coat = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
W, H = 160, 96

s = start_scene(addon_from_path=True)
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = W, H, 100
world = bpy.data.worlds.new("Sky"); s.world = world
bg = world.node_tree.nodes["Background"]; bg.inputs["Color"].default_value = (0.35, 0.5, 0.8, 1.0)
bg.inputs["Strength"].default_value = 0.6
ground = bpy.data.materials.new("Ground"); gp = ground.node_tree.nodes["Principled BSDF"]
gp.inputs["Base Color"].default_value = (0.3, 0.3, 0.3, 1.0); gp.inputs["Roughness"].default_value = 0.9
bpy.ops.mesh.primitive_plane_add(size=30.0); bpy.context.object.data.materials.append(ground)
car = car_body((0.0, 0.0, 0.3), car_paint(coat_weight=coat))
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN")); sun.data.energy = 3.0
sun.data.angle = math.radians(1.0)
sun.rotation_euler = (math.radians(60), 0.0, math.radians(-40)); s.collection.objects.link(sun)
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam")); cam.data.lens = 50
cam.location = (0.3, -4.2, 1.3); cam.rotation_euler = (math.radians(77), 0.0, math.radians(4))
s.collection.objects.link(cam); s.camera = cam


ref_path, mask_path = out / f"cycles_{cyc_spp}_{coat:g}.npy", out / "mask.npy"
if not ref_path.exists():
    unbiased_cycles(s, cyc_spp)
    car.pass_index = 1; s.view_layers[0].use_pass_object_index = True
    s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    s.render.filepath = str(out / "cycles.exr"); s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    ch = read_exr_layers(out / "cycles.exr")
    np.save(ref_path, np.stack([ch[f"ViewLayer.Combined.{c}"] for c in "RGB"], -1).astype(np.float64))
    np.save(mask_path, np.rint(ch["ViewLayer.Object Index.X"]) == 1)
ref, mask = np.load(ref_path), np.load(mask_path)

from addon.export import export_scene  # noqa: E402
from stpm_core.compare.metrics import flip_error  # noqa: E402
from stpm_core.render import render  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402
core, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: s.frame_set(f, subframe=sub))[:2]
for w in warnings:
    if "Coat" in str(w):
        print("warning:", w)
res = render(core, RenderSettings(samples=stpm_spp, seed=1))
img = np.asarray(res.passes["Combined"][..., :3], np.float64)
np.save(out / f"stpm_{coat:g}.npy", img)
ys, xs = np.nonzero(mask)
box = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
f_all, _ = flip_error(img, ref)
f_box, _ = flip_error(img[box], ref[box])
print(f"car pixels {int(mask.sum())}: mean STPM / Cycles {img[mask].mean() / ref[mask].mean():.3f}; "
      f"FLIP whole {f_all:.4f}, car box {f_box:.4f}; image mean ratio {img.mean() / ref.mean():.3f}")
