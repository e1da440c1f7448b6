"""What the car paint's Coat (Principled Coat Weight 1, roughness 0.03; STPM does not render it,
warned) is worth in Cycles on review/out/outdoor_fair.blend: Cycles at SPP with the coat as saved and
with Coat Weight 0, mean of the car's pixels (Object Index pass) and the ratio.
python review/coat_probe.py [SPP]"""
import sys
from pathlib import Path
import numpy as np
import bpy
import OpenImageIO as oiio
HERE = Path(__file__).resolve().parent
spp = int(sys.argv[1]) if len(sys.argv) > 1 else 64
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "outdoor_fair.blend"))
s = bpy.context.scene; s.frame_set(10); s.render.engine = "CYCLES"; cy = s.cycles
cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", spp, False, False
cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
bpy.data.objects["CarBody"].pass_index = 1
s.view_layers[0].use_pass_object_index = True
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
means = []
for coat in (1.0, 0.0):
    bpy.data.materials["CarPaint"].node_tree.nodes["Principled BSDF"].inputs["Coat Weight"].default_value = coat
    s.render.filepath = str(HERE / "out" / f"outdoor_coat{coat:g}.exr"); s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    inp = oiio.ImageInput.open(s.render.filepath); sub = 0; ch = {}
    while inp.seek_subimage(sub, 0):
        sp = inp.spec(); px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, -1)
        ch.update({n: px[..., i] for i, n in enumerate(sp.channelnames)}); sub += 1
    m = np.rint(ch["ViewLayer.Object Index.X"]) == 1
    means.append(np.mean([ch[f"ViewLayer.Combined.{c}"][m].mean() for c in "RGB"]))
print(f"car pixels: coat 1 {means[0]:.4f}, coat 0 {means[1]:.4f}, ratio coat 0 / coat 1 {means[1] / means[0]:.3f}")
