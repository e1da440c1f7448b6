"""Per-object comparison on review/out/outdoor_fair.blend: renders Cycles' Object Index pass (1 spp,
frame 10, the frame's instant: moving objects' blur is not in the mask), then for each test EXR the
mean ratio against the reference per object, and the share of each object's pixels whose LDR-FLIP
exceeds 0.2.  python review/outdoor_regions.py REF.exr TEST.exr [TEST2.exr ...]"""
import sys
from pathlib import Path
import numpy as np
import bpy
import OpenImageIO as oiio
import flip_evaluator as flip

HERE = Path(__file__).resolve().parent
OBJECTS = ["Ground", "CarBody", "Turntable", "Puddle", "Bottle", "RockPatch", "Pole"]


def combined(path):
    inp = oiio.ImageInput.open(str(path)); sub = 0; ch = {}
    while inp.seek_subimage(sub, 0):
        sp = inp.spec(); px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, -1)
        ch.update({n: px[..., i] for i, n in enumerate(sp.channelnames)}); sub += 1
    for pre in ("ViewLayer.Combined.", "Combined.", ""):
        if pre + "R" in ch:
            return np.stack([ch[pre + c] for c in "RGB"], -1).astype(np.float64)


def srgb(x):
    x = np.clip(np.nan_to_num(x), 0, 1); return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "outdoor_fair.blend"))
s = bpy.context.scene; s.frame_set(10); s.render.engine = "CYCLES"; s.cycles.samples = 1
s.render.use_motion_blur = False; s.camera.data.dof.use_dof = False
for i, n in enumerate(OBJECTS, 1):
    bpy.data.objects[n].pass_index = i
s.view_layers[0].use_pass_object_index = True
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
s.render.filepath = str(HERE / "out" / "outdoor_index.exr"); s.render.use_file_extension = False
bpy.ops.render.render(write_still=True)
inp = oiio.ImageInput.open(s.render.filepath); sub = 0; idx = None
while inp.seek_subimage(sub, 0):
    sp = inp.spec()
    if any("IndexOB" in n or "Object Index" in n for n in sp.channelnames):
        idx = np.rint(inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, -1)[..., 0]).astype(int)
    sub += 1
ref = combined(sys.argv[1])
print(f"{'object':10s} {'px':>5s} " + " ".join(f"{Path(t).stem[-18:]:>26s}" for t in sys.argv[2:]))
tests = [combined(t) for t in sys.argv[2:]]
flips = [flip.evaluate(srgb(ref).astype(np.float32), srgb(t).astype(np.float32), "LDR")[0] for t in tests]
for i, n in [(0, "sky")] + list(enumerate(OBJECTS, 1)):
    m = idx == i
    cells = [f"{t[m].mean() / ref[m].mean():.3f} ({(f[m] > 0.2).mean():.2f} >0.2)" for t, f in zip(tests, flips)]
    print(f"{n:10s} {int(m.sum()):5d} " + " ".join(f"{c:>26s}" for c in cells))
