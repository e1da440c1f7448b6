import sys
from pathlib import Path; ROOT = Path(__file__).resolve().parents[2]; sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy, OpenImageIO as oiio
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
for crop in (False, True):
    s = fresh(); add_camera(); add_light(location=(1, -2, 3), energy=500); set_world((0.1, 0.1, 0.1))
    add_mesh("plane", "Floor", size=8); add_mesh("cube", "Box")
    s.render.engine = "CYCLES"; s.cycles.samples = 4; s.cycles.use_denoising = False
    s.render.resolution_x, s.render.resolution_y = 40, 30
    r = s.render; r.use_border = True; r.use_crop_to_border = crop
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.25, 0.75, 0.1, 0.5
    s.view_layers[0].use_pass_z = True
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"; r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.filepath = f"/tmp/ar2_border{crop}.exr"; r.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    inp = oiio.ImageInput.open(r.filepath); sub = 0
    while inp.seek_subimage(sub, 0):
        sp = inp.spec(); px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, sp.nchannels)
        print("crop", crop, sp.width, sp.height, sp.full_width, sp.full_height, sp.x, sp.y, list(sp.channelnames), "corner", px[0, 0].tolist(), "centre-bottom", px[sp.height - 5, sp.width // 2].tolist())
        sub += 1
