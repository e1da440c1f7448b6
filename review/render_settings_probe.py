"""Do ordinary Blender render settings take effect with engine STPM?  Tiny scene, F12 through bpy.

film_transparent (alpha 0 on background), resolution_percentage 50, render region (use_border +
use_crop_to_border), and the Cycles-named Max Bounces. python review/render_settings_probe.py"""
import sys, math
from pathlib import Path
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
from test_addon_render import _render_to_exr, _tiny
OUT = ROOT / "review" / "out"

def scene():
    s = fresh(); add_camera(); add_light(location=(0, -2, 3)); set_world((0.2, 0.2, 0.2))
    add_mesh("cube", "Box"); s.render.engine = "STPM"; _tiny(s, samples=2, photons=2000)
    s.render.resolution_x, s.render.resolution_y = 64, 48
    return s

def combined(p):
    k = [k for k in p if k.endswith("Combined") or k == "Combined"]
    return p[k[0]] if k else p

s = scene(); s.render.film_transparent = True
p = _render_to_exr(s, OUT / "probe_transparent.exr"); c = combined(p)
print("film_transparent: shape", c.shape, "alpha corner", c[0, 0, 3], "alpha centre", c[24, 32, 3])
s = scene(); s.render.resolution_percentage = 50
c = combined(_render_to_exr(s, OUT / "probe_pct.exr")); print("resolution 50%: shape", c.shape)
s = scene(); s.render.use_border = True; s.render.use_crop_to_border = True
s.render.border_min_x, s.render.border_max_x, s.render.border_min_y, s.render.border_max_y = 0.25, 0.75, 0.25, 0.75
c = combined(_render_to_exr(s, OUT / "probe_border.exr")); print("border crop: shape", c.shape, "(Cycles: 24x32)")
s = scene(); s.render.use_border = True; s.render.use_crop_to_border = False
s.render.border_min_x, s.render.border_max_x, s.render.border_min_y, s.render.border_max_y = 0.25, 0.75, 0.25, 0.75
c = combined(_render_to_exr(s, OUT / "probe_border_nocrop.exr")); print("border no crop: shape", c.shape, "corner", c[0, 0], "centre", c[24, 32])
