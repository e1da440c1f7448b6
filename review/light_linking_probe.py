"""How much Blender 4's light linking changes review/out/outdoor.blend in Cycles (STPM ignores it,
warned): Cycles at SPP with the CarKey light linked to the car only (as saved) and unlinked, mean
ratio unlinked / linked over a 3 x 3 grid.  python review/light_linking_probe.py [SPP]"""
import sys
import numpy as np
import bpy
import OpenImageIO as oiio
from _review_common import HERE, unbiased_cycles
spp = int(sys.argv[1]) if len(sys.argv) > 1 else 32
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "outdoor.blend"))
s = bpy.context.scene; s.frame_set(10); unbiased_cycles(s, spp)
s.render.image_settings.media_type = "IMAGE"; s.render.image_settings.file_format = "OPEN_EXR"
imgs = []
for tag in ("linked", "unlinked"):
    if tag == "unlinked":
        bpy.data.objects["CarKey"].light_linking.receiver_collection = None
    s.render.filepath = str(HERE / "out" / f"outdoor_cycles_{tag}.exr"); bpy.ops.render.render(write_still=True)
    imgs.append(oiio.ImageBuf(s.render.filepath).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64))
a, b = imgs
H, W = a.shape[:2]
print("whole image unlinked / linked:", round(b.mean() / a.mean(), 4))
for i in range(3):
    print("grid", "  ".join(f"{b[i*H//3:(i+1)*H//3, j*W//3:(j+1)*W//3].mean() / a[i*H//3:(i+1)*H//3, j*W//3:(j+1)*W//3].mean():.3f}" for j in range(3)))
