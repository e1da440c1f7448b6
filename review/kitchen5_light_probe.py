"""One light of review/out/kitchen5.blend at a time: STPM against Cycles, whole image and 20-px blocks.

python review/kitchen5_light_probe.py LIGHT [--diffuse-tiles] [--no-normalmap] [--thick] [--fg] [--no-photons]
LIGHT: Sun, CounterArea, TableSpot, Shade (the pendant's emissive shade) or World; the others are off.
View layer Main alone, no region, no compositor, frame 2.  Cycles: 256 spp, full bounces, clamps off, Filter
Glossy 0 (the file's 1.0 rounds the tiles' sharp lobe after a diffuse bounce: Cycles 5.3 % dark); STPM: 32 spp,
1 M global / 200 k caustic photons, k 100, no adaptive sampling.
--diffuse-tiles: the tiles' Principled at roughness 1, Specular IOR Level 0; --no-normalmap: the tiles'
normal map unlinked; --thick: the two walls 0.25 m thick instead of 0.1; --fg: STPM with Final Gather
Samples 16; --no-photons: STPM without photons against Cycles with Diffuse Bounces 0 (both: direct light
plus paths through glossy and transmissive lobes to a diffuse vertex).
Writes review/out/k5probe_{cycles,stpm}_<tag>.exr and prints the mean ratio and the block ratios.
"""
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import bpy  # noqa: E402
import OpenImageIO as oiio  # noqa: E402
import addon  # noqa: E402

addon.register()
args = sys.argv[1:]
light = args[0]
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "kitchen5.blend"))
s = bpy.context.scene
s.frame_set(2)
s.view_layers["NoFruit"].use = False
s.render.use_compositing = False
s.render.use_border = False
for n in ("Sun", "CounterArea", "TableSpot"):
    if n != light:
        s.objects[n].data.energy = 0
if light != "Shade":
    bpy.data.materials["ShadeGlow"].node_tree.nodes["Emission"].inputs["Strength"].default_value = 0
if light != "World":
    s.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0
tiles = bpy.data.materials["Tiles"].node_tree
if "--diffuse-tiles" in args:
    b = tiles.nodes["Principled BSDF"]
    b.inputs["Roughness"].default_value = 1.0
    b.inputs["Specular IOR Level"].default_value = 0.0
if "--no-normalmap" in args:
    for link in list(tiles.nodes["Principled BSDF"].inputs["Normal"].links):
        tiles.links.remove(link)
if "--thick" in args:      # outer faces moved out (object space: the walls' centres are at 0)
    for v in s.objects["WallBack"].data.vertices:
        if v.co.y > 0:
            v.co.y = 0.2
    for v in s.objects["WallLeft"].data.vertices:
        if v.co.x < 0:
            v.co.x = -0.2
    s.objects["WallBack"].data.update()
    s.objects["WallLeft"].data.update()
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
s.render.image_settings.color_depth = "32"
s.render.use_file_extension = False
tag = light + "".join(a for a in args[1:])
no_photons = "--no-photons" in args

s.render.engine = "CYCLES"
cy = s.cycles
cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", 256, False, False
cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
cy.blur_glossy = 0.0
cy.seed = 4
if no_photons:
    cy.diffuse_bounces = 0
c_path = HERE / "out" / f"k5probe_cycles_{tag.replace('--fg', '')}.exr"
t = time.time()
if not ("--fg" in args and c_path.exists()):      # --fg reuses the light's Cycles image
    s.render.filepath = str(c_path)
    bpy.ops.render.render(write_still=True)
tc = time.time() - t

s.render.engine = "STPM"
st = s.stpm
st.samples, st.k_nearest, st.use_adaptive_sampling = 32, 100, False
st.photons_global, st.photons_caustic = (0, 0) if no_photons else (1_000_000, 200_000)
if "--fg" in args:
    st.final_gather_samples = 16
s_path = HERE / "out" / f"k5probe_stpm_{tag}.exr"
s.render.filepath = str(s_path)
t = time.time()
bpy.ops.render.render(write_still=True)
ts = time.time() - t


def combined(path):
    """(H, W, 3) Combined of view layer Main in a multilayer EXR."""
    inp = oiio.ImageInput.open(str(path))
    sub, chans = 0, {}
    while inp.seek_subimage(sub, 0):
        sp = inp.spec()
        px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, sp.nchannels)
        for i, n in enumerate(sp.channelnames):
            chans[n] = px[..., i]
        sub += 1
    return np.stack([chans[f"Main.Combined.{c}"] for c in "RGB"], -1).astype(np.float64)


c, x = combined(c_path), combined(s_path)
print(f"{tag}: cycles {tc:.0f} s, stpm {ts:.0f} s; mean ratio {x.mean() / c.mean():.4f}")
b = 20
H, W = c.shape[:2]
rows = [[x[y:y + b, u:u + b].mean() / max(c[y:y + b, u:u + b].mean(), 1e-6) for u in range(0, W - b + 1, b)]
        for y in range(0, H - b + 1, b)]
np.set_printoptions(linewidth=200)
print(np.array(rows).round(2))
