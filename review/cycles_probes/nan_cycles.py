import sys, math
from pathlib import Path; ROOT = Path(__file__).resolve().parents[2]; sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
def build(kind):
    s = fresh(); add_camera(); add_light(location=(1, -2, 3), energy=500); set_world((0.1, 0.1, 0.1))
    add_mesh("plane", "Floor", size=8)
    o = add_mesh("cube", "Box")
    if kind == "nan":
        o.keyframe_insert("location", frame=1); o.location.x = float("nan"); o.keyframe_insert("location", frame=2)
        s.render.use_motion_blur = True; s.frame_set(1)
    if kind == "nanframe":   # the frame itself NaN
        o.location.x = float("nan")
    if kind == "none": bpy.data.objects.remove(o)
    s.render.engine = "CYCLES"; s.cycles.samples = 16; s.cycles.use_denoising = False
    s.render.resolution_x, s.render.resolution_y = 32, 24
    s.render.image_settings.file_format = "OPEN_EXR"; s.render.filepath = f"/tmp/ar2_nan_{kind}.exr"; s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    import OpenImageIO as oiio
    a = oiio.ImageBuf(f"/tmp/ar2_nan_{kind}.exr").get_pixels(oiio.FLOAT)
    print(kind, "mean", np.nanmean(a[..., :3]), "finite", np.isfinite(a).all())
for k in ("static", "nan", "nanframe", "none"): build(k)
