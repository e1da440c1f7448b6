"""How much the brushed-metal lamp's anisotropy changes Cycles' image (artist review 3): the floor lamp head of
review/out/interior.blend close up (200 x 200, 64 spp, direct light + glossy bounces), Principled Anisotropic 0.8
against 0; STPM renders both as 0.  PYTHONPATH=. python review/aniso_probe.py"""
import sys, tempfile
from pathlib import Path
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent)); sys.path.insert(0, str(HERE.parent / "tests"))
import numpy as np
import bpy
from mathutils import Vector
from cycles_ref import render_cycles
out = {}
for aniso in (0.8, 0.0):
    bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
    s = bpy.context.scene; s.frame_set(12)
    cam = s.camera; cam.animation_data_clear(); cam.location = (0.0, -2.35, 1.6)
    cam.rotation_euler = (Vector((1.8, 1.2, 1.55)) - cam.location).to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = 150; cam.data.dof.use_dof = False
    s.render.resolution_x = s.render.resolution_y = 200
    bpy.data.materials["BrushedMetal"].node_tree.nodes["Principled BSDF"].inputs["Anisotropic"].default_value = aniso
    out[aniso] = render_cycles(s, Path(tempfile.mkdtemp()), samples=64, seeds=(0,), max_bounces=4)[0]
a, b = out[0.8], out[0.0]
head = b.mean(-1) > 0        # the whole close-up
diff = np.abs(a - b).mean(-1)
print(f"close-up mean: aniso 0.8 {a.mean():.4f}, aniso 0 {b.mean():.4f} (ratio {a.mean() / b.mean():.3f}); "
      f"mean |diff| {diff.mean():.4f}; pixels differing by > 20 %: {np.mean(diff > 0.2 * np.maximum(b.mean(-1), 1e-3)):.3f}")
