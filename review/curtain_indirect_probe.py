"""The curtains' indirect light (artist review 3): STPM's Indirect on the alpha-masked lace curtains of
review/out/interior.blend against Cycles' (a 1024-spp render minus a 128-spp direct-light render, made by
render_interior_cycles.py and the direct-only settings of direct_light_probe.py).

PYTHONPATH=. python review/curtain_indirect_probe.py FG [ALPHA]   FG: final_gather_samples; ALPHA 1: the lace's
Alpha unlinked (an opaque curtain).  8 spp, 1M global photons, k 100, 320 x 180, frame 12, F12's export.
Environment: STPM_PLANE, STPM_FRONT the tangent slab's fractions behind and in front of the plane
(estimators.PLANE_FRACTION, PLANE_FRONT; inf: no bound), STPM_REF the
Cycles reference's tag (default ref1024: review/out/interior_cycles_<tag>.exr), STPM_DIRECT the direct one's
(default direct128)."""
import os
import sys
from pathlib import Path
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import numpy as np
import bpy, addon, OpenImageIO as oiio
addon.register()
from addon.batch import render_visibility
from addon.export import export_scene
from stpm_core.render import render
from stpm_core.settings import RenderSettings
from stpm_core.photons import estimators
if "STPM_PLANE" in os.environ:
    estimators.PLANE_FRACTION = float(os.environ["STPM_PLANE"])
if "STPM_FRONT" in os.environ:
    estimators.PLANE_FRONT = float(os.environ["STPM_FRONT"])
fg = int(sys.argv[1]); opaque = len(sys.argv) > 2 and sys.argv[2] == "1"
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
s = bpy.context.scene; s.frame_set(12)
if opaque:
    nt = bpy.data.materials["Lace"].node_tree
    for l in list(nt.links):
        if l.to_socket.name == "Alpha":
            nt.links.remove(l)
with render_visibility(bpy.context.view_layer):
    core = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: s.frame_set(f, subframe=sub))[0]
r = render(core, RenderSettings(samples=8, photons_global=1_000_000, photons_caustic=0, k_nearest=100,
                                 final_gather_samples=fg, seed=3))
ind = np.asarray(r.passes["Indirect"])[..., :3].astype(np.float64)
def layers(p):
    i = oiio.ImageInput.open(p); out = {}; sub = 0
    while i.seek_subimage(sub, 0):
        sp = i.spec(); px = i.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, -1)
        out.update({n: px[..., c] for c, n in enumerate(sp.channelnames)}); sub += 1
    return np.stack([out[c] for c in "RGB"], -1)
ref, direct = os.environ.get("STPM_REF", "ref1024"), os.environ.get("STPM_DIRECT", "direct128")
cyc = layers(str(HERE / f"out/interior_cycles_{ref}.exr")) - layers(str(HERE / f"out/interior_cycles_{direct}.exr"))
B = 20; H, W = cyc.shape[:2]; h, w = H // B, W // B
blk = lambda x: x[:h * B, :w * B].mean(-1).reshape(h, B, w, B).mean((1, 3))
ratio = blk(ind) / np.maximum(blk(cyc), 1e-9)
cur = [(1, 12), (0, 5), (1, 7), (2, 7), (1, 13)]
print(f"fg {fg}, opaque {opaque}: curtain blocks STPM/Cycles indirect", [round(float(ratio[b]), 3) for b in cur],
      f"; wall blocks (1, 1), (1, 15): {ratio[1, 1]:.3f} {ratio[1, 15]:.3f}; image {ind.mean() / cyc.mean():.3f}",
      f"; slab {estimators.PLANE_FRACTION} {estimators.PLANE_FRONT};",
      f"look-ups {r.stats.get('photon_lookup_s', float('nan')):.1f} s")
np.save(HERE / "out" / f"curtain_ratio_fg{fg}_plane{estimators.PLANE_FRACTION}_{estimators.PLANE_FRONT}.npy", ratio)
np.save(HERE / "out" / f"curtain_indirect_fg{fg}_plane{estimators.PLANE_FRACTION}_{estimators.PLANE_FRONT}.npy", ind)
np.save(HERE / "out" / f"curtain_indirect_cycles_{ref}.npy", cyc)
