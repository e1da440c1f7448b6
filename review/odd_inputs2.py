"""What artists do wrong, each alone in a tiny scene, rendered through F12 (32x24, 1 spp):
a missing texture, a non-manifold mesh, zero-area faces, NaN in a keyframe, a shader node STPM
does not know, samples 0, a light node tree with a constant Emission colour / strength.
python review/odd_inputs2.py [case ...]   (PYTHONPATH = checkout)"""
import math, sys, traceback
from pathlib import Path
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
from test_addon_render import _render_to_exr, _tiny
from addon.engine import LAST_RENDER
OUT = ROOT / "review" / "out"; OUT.mkdir(exist_ok=True)

def base():
    s = fresh(); s.render.engine = "STPM"; add_camera(); add_light(location=(1, -2, 3), energy=500); set_world((0.1, 0.1, 0.1))
    add_mesh("plane", "Floor", size=8); _tiny(s, samples=2, photons=5000); return s

def missing_texture(s):
    o = add_mesh("cube", "Box"); m = bpy.data.materials.new("T"); nt = m.node_tree
    t = nt.nodes.new("ShaderNodeTexImage"); im = bpy.data.images.new("wood.png", 4, 4); im.source = "FILE"; im.filepath = "/nonexistent/wood.png"; t.image = im
    nt.links.new(t.outputs[0], nt.nodes["Principled BSDF"].inputs["Base Color"]); o.data.materials.append(m)
def non_manifold(s):
    me = bpy.data.meshes.new("NM")   # three faces on one edge, a dangling edge, a lone vertex
    v = [(0, 0, 0), (1, 0, 0), (0.5, 1, 0), (0.5, -1, 0), (0.5, 0, 1), (2, 2, 2), (3, 3, 3)]
    me.from_pydata(v, [(5, 6)], [(0, 1, 2), (0, 1, 3), (0, 1, 4)]); me.update()
    s.collection.objects.link(bpy.data.objects.new("NM", me))
def zero_area(s):
    me = bpy.data.meshes.new("Z")
    v = [(0, 0, 0.5), (1, 0, 0.5), (2, 0, 0.5), (0, 0, 0.5), (0, 1, 0.5)]
    me.from_pydata(v, [], [(0, 1, 2), (0, 3, 4), (0, 1, 4)]); me.update()   # collinear, degenerate (dup vertex), one real
    s.collection.objects.link(bpy.data.objects.new("Z", me))
def nan_keyframe(s):
    o = add_mesh("cube", "Box"); o.keyframe_insert("location", frame=1); o.location.x = float("nan"); o.keyframe_insert("location", frame=2)
    s.render.use_motion_blur = True; s.frame_set(1)
def nan_scale_key(s):
    o = add_mesh("cube", "Box"); o.keyframe_insert("scale", frame=1); o.scale = (float("inf"), 1, 1); o.keyframe_insert("scale", frame=2)
    s.render.use_motion_blur = True; s.frame_set(1)
def unknown_node(s):
    o = add_mesh("cube", "Box"); m = bpy.data.materials.new("Toon"); nt = m.node_tree; nt.nodes.remove(nt.nodes["Principled BSDF"])
    t = nt.nodes.new("ShaderNodeBsdfToon"); nt.links.new(t.outputs[0], nt.nodes["Material Output"].inputs[0]); o.data.materials.append(m)
def hair_bsdf(s):
    o = add_mesh("cube", "Box"); m = bpy.data.materials.new("H"); nt = m.node_tree; nt.nodes.remove(nt.nodes["Principled BSDF"])
    t = nt.nodes.new("ShaderNodeBsdfHairPrincipled"); nt.links.new(t.outputs[0], nt.nodes["Material Output"].inputs[0]); o.data.materials.append(m)
def zero_samples(s):
    add_mesh("cube", "Box")
    try: s.stpm.samples = 0
    except Exception as e: print("   setting samples=0 raised", type(e).__name__, e)
    print("   samples now", s.stpm.samples)
def light_const_nodes(s):
    add_mesh("cube", "Box"); l = bpy.data.lights["Light"]; l.use_nodes = True
    e = l.node_tree.nodes["Emission"]; e.inputs["Color"].default_value = (1, 0.2, 0.2, 1); e.inputs["Strength"].default_value = 3
def light_blackbody(s):   # evaluated since this review (addon/export/blackbody.py)
    add_mesh("cube", "Box"); l = bpy.data.lights["Light"]; l.use_nodes = True; nt = l.node_tree
    bb = nt.nodes.new("ShaderNodeBlackbody"); bb.inputs[0].default_value = 2500; nt.links.new(bb.outputs[0], nt.nodes["Emission"].inputs["Color"])
def zero_size_area(s):
    add_mesh("cube", "Box"); a = add_light("AREA", "A", location=(0, 0, 3), energy=100); a.data.size = 0.0
def zero_scale_object(s):
    o = add_mesh("cube", "Box"); o.scale = (0, 1, 1)
def camera_inside_glass(s):
    o = add_mesh("sphere", "G", location=(0, -6, 2), radius=0.5); m = bpy.data.materials.new("G"); nt = m.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"]); g = nt.nodes.new("ShaderNodeBsdfGlass"); nt.links.new(g.outputs[0], nt.nodes["Material Output"].inputs[0]); o.data.materials.append(m)
def lens_zero_clip(s):
    add_mesh("cube", "Box"); s.camera.data.clip_start = 1e-6; s.camera.data.clip_end = 1e12

cases = {n: f for n, f in list(globals().items()) if callable(f) and getattr(f, "__module__", "") == "__main__" and n not in ("base",)}
for name in (sys.argv[1:] or cases):
    s = base(); cases[name](s); LAST_RENDER.clear()
    try:
        p = _render_to_exr(s, OUT / f"odd2_{name}.exr"); c = p["Combined"][..., :3]
        print(f"[{name}] rendered: mean {np.nanmean(c):.4f} finite {np.isfinite(c).all()} warnings={LAST_RENDER.get('warnings')}")
    except Exception as e:
        print(f"[{name}] RAISED {type(e).__name__}: {e}"); traceback.print_exc(limit=2)
    if not LAST_RENDER: print(f"   [{name}] no LAST_RENDER: the engine did not finish (see the report above)")
