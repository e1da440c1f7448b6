import sys
from pathlib import Path; ROOT = Path(__file__).resolve().parents[2]; sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy, OpenImageIO as oiio
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
from test_addon_render import _render_to_exr, _tiny
def scene():
    s = fresh(); add_camera(); add_light(location=(1, -2, 3), energy=500); set_world((0.3, 0.3, 0.3))
    o = add_mesh("sphere", "G", radius=1.2); m = bpy.data.materials.new("G"); nt = m.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"]); g = nt.nodes.new("ShaderNodeBsdfGlass"); nt.links.new(g.outputs[0], nt.nodes["Material Output"].inputs[0]); o.data.materials.append(m)
    s.render.film_transparent = True; s.render.resolution_x, s.render.resolution_y = 32, 24
    return s
for tg in (False, True):
    s = scene(); s.cycles.film_transparent_glass = tg
    s.render.engine = "CYCLES"; s.cycles.samples = 16; s.cycles.use_denoising = False
    s.render.image_settings.file_format = "OPEN_EXR"; s.render.filepath = f"/tmp/ar2_tg{tg}.exr"; s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    a = oiio.ImageBuf(s.render.filepath).get_pixels(oiio.FLOAT)
    print("cycles transparent_glass", tg, "alpha centre", a[12, 16, 3], "rgb", a[12, 16, :3])
s = scene(); s.render.engine = "STPM"; _tiny(s, samples=4, photons=0); s.render.resolution_x, s.render.resolution_y = 32, 24
s.cycles.film_transparent_glass = True
p = _render_to_exr(s, __import__("pathlib").Path("/tmp/ar2_tg_stpm.exr"))
print("stpm alpha centre", p["Combined"][12, 16, 3], "rgb", p["Combined"][12, 16, :3])
from addon.engine import LAST_RENDER; print(LAST_RENDER.get("warnings"))
