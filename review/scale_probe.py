"""Does a scene render the same at 1 mm, 1 m and 1 km?  Everything (objects, camera, clipping,
DoF distance) scaled by S; lit by a sun and a constant world, which do not depend on scale.

python review/scale_probe.py [S ...]   (PYTHONPATH = checkout; renders 64x48 through F12)
Prints the image mean and 4x4 grid ratios of each scale against S = 1."""
import math, sys
from pathlib import Path
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world
from test_addon_render import _render_to_exr
OUT = ROOT / "review" / "out"; OUT.mkdir(exist_ok=True)
scales = [float(a) for a in sys.argv[1:]] or [1.0, 1000.0, 0.001]

def build(S):
    s = fresh(); s.render.engine = "STPM"
    cam = add_camera(location=(0, -6 * S, 2 * S)); cam.data.clip_start, cam.data.clip_end = 0.1 * S, 100 * S
    add_light("SUN", "Sun", location=(0, 0, 5 * S), energy=3.0, angle=math.radians(2)).rotation_euler = (math.radians(30), 0, math.radians(20))
    set_world((0.2, 0.22, 0.25))
    floor = add_mesh("plane", "Floor", size=10 * S)
    box = add_mesh("cube", "Box", location=(-1.2 * S, 0, 0.5 * S), size=1 * S)
    sph = add_mesh("sphere", "Glass", location=(1.0 * S, 0, 0.7 * S), radius=0.7 * S)
    m = bpy.data.materials.new("G"); nt = m.node_tree; nt.nodes.remove(nt.nodes["Principled BSDF"])
    g = nt.nodes.new("ShaderNodeBsdfGlass"); nt.links.new(g.outputs[0], nt.nodes["Material Output"].inputs[0]); sph.data.materials.append(m)
    bpy.context.view_layer.objects.active = sph; bpy.ops.object.shade_smooth()
    st = s.stpm; st.samples, st.photons_global, st.photons_caustic, st.k_nearest, st.seed = 16, 100000, 100000, 50, 1
    s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 64, 48, 100
    return s

res = {}
for S in scales:
    p = _render_to_exr(build(S), OUT / f"scale_{S:g}.exr")
    res[S] = p
    c = p["Combined"][..., :3]
    print(f"S={S:g}: mean {c.mean():.5f}  finite {np.isfinite(c).all()}  caustic {p['Caustic'].mean():.5f} indirect {p['Indirect'].mean():.5f} depth median {np.median(p['Depth']):.4g}")
ref = res[scales[0]]["Combined"][..., :3]
for S in scales[1:]:
    a = res[S]["Combined"][..., :3]; h, w = a.shape[:2]
    print(f"S={S:g} / S={scales[0]:g}: mean ratio {a.mean() / ref.mean():.4f}")
    for i in range(4):
        print("   ", " ".join(f"{a[i*h//4:(i+1)*h//4, j*w//4:(j+1)*w//4].mean() / max(ref[i*h//4:(i+1)*h//4, j*w//4:(j+1)*w//4].mean(), 1e-9):6.3f}" for j in range(4)))
