import sys
from pathlib import Path; ROOT = Path(__file__).resolve().parents[2]; sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy, OpenImageIO as oiio
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
for kind in ("ok", "nan", "none"):
    s = fresh(); add_camera(); add_light(location=(1, -2, 3), energy=500); set_world((0.1, 0.1, 0.1))
    add_mesh("plane", "Floor", size=8); add_mesh("cube", "Box")
    l2 = add_light(name="L2", location=(-1, -1, 2), energy=300)
    if kind == "nan": l2.location.x = float("nan")
    if kind == "none": bpy.data.objects.remove(l2)
    s.render.engine = "CYCLES"; s.cycles.samples = 16; s.cycles.use_denoising = False
    s.render.resolution_x, s.render.resolution_y = 32, 24
    s.render.image_settings.file_format = "OPEN_EXR"; s.render.filepath = f"/tmp/ar2_nl_{kind}.exr"; s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    a = oiio.ImageBuf(f"/tmp/ar2_nl_{kind}.exr").get_pixels(oiio.FLOAT)
    print(kind, "mean", np.nanmean(a[..., :3]), "finite", np.isfinite(a).all())
