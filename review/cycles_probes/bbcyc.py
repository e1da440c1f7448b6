import sys
from pathlib import Path; ROOT = Path(__file__).resolve().parents[2]; sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy, OpenImageIO as oiio
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
def run(kind, T):
    s = fresh(); add_camera(); L = add_light(location=(1, -2, 3), energy=500); set_world((0, 0, 0))
    add_mesh("plane", "Floor", size=8)
    l = L.data
    if kind == "node":
        l.use_nodes = True; nt = l.node_tree; bb = nt.nodes.new("ShaderNodeBlackbody"); bb.inputs[0].default_value = T
        nt.links.new(bb.outputs[0], nt.nodes["Emission"].inputs["Color"])
    else:
        l.use_temperature = True; l.temperature = T
    s.render.engine = "CYCLES"; s.cycles.samples = 8; s.cycles.use_denoising = False; s.cycles.max_bounces = 0
    s.render.resolution_x, s.render.resolution_y = 32, 24
    s.render.image_settings.file_format = "OPEN_EXR"; s.render.filepath = f"/tmp/ar2_bb_{kind}.exr"; s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    a = oiio.ImageBuf(s.render.filepath).get_pixels(oiio.FLOAT)[..., :3]
    return a.reshape(-1, 3).mean(0)
for T in (1000, 2500, 4000, 9000):
    a, b = run("node", T), run("temp", T); print(T, "node", np.round(a, 4), "temperature", np.round(b, 4), "ratio", np.round(a / np.maximum(b, 1e-9), 4))
