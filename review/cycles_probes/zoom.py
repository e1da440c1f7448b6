import sys, math
from pathlib import Path; ROOT = Path(__file__).resolve().parents[2]; sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy, OpenImageIO as oiio
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
def run(zoom):
    s = fresh(); add_camera(location=(0, -6, 0), rotation=(math.radians(90), 0, 0)); add_light(location=(0, -3, 3), energy=1000); set_world((0.05,0.05,0.05))
    for x in (-1.5, 0, 1.5): add_mesh("cube", f"B{x}", location=(x, 0, 0), size=0.4)
    s.render.use_motion_blur = True
    cam = s.camera.data
    if zoom: cam.keyframe_insert("lens", frame=1); cam.lens = 80; cam.keyframe_insert("lens", frame=2)
    s.frame_set(1); s.render.motion_blur_position = "START"; s.render.motion_blur_shutter = 1.0
    s.render.engine = "CYCLES"; s.cycles.samples = 16; s.cycles.use_denoising = False
    s.render.resolution_x, s.render.resolution_y = 64, 48
    s.render.image_settings.file_format = "OPEN_EXR"; s.render.filepath = f"/tmp/ar2_zoom{zoom}.exr"; s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    a = oiio.ImageBuf(f"/tmp/ar2_zoom{zoom}.exr").get_pixels(oiio.FLOAT)[..., :3].mean(-1)
    row = a[24]; print("zoom", zoom, "lit columns", np.where(row > 0.2 * row.max())[0].tolist())
run(0); run(1)
