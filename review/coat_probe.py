"""What the car paint's Coat (Principled Coat Weight 1, roughness 0.03; STPM does not render it,
warned) is worth in Cycles on review/out/outdoor_fair.blend: Cycles at SPP with the coat as saved and
with Coat Weight 0, mean of the car's pixels (Object Index pass) and the ratio.
python review/coat_probe.py [SPP]"""
import sys
import numpy as np
import bpy
from _review_common import HERE, read_exr_layers, unbiased_cycles
spp = int(sys.argv[1]) if len(sys.argv) > 1 else 64
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "outdoor_fair.blend"))
s = bpy.context.scene; s.frame_set(10); unbiased_cycles(s, spp)
bpy.data.objects["CarBody"].pass_index = 1
s.view_layers[0].use_pass_object_index = True
s.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
means = []
for coat in (1.0, 0.0):
    bpy.data.materials["CarPaint"].node_tree.nodes["Principled BSDF"].inputs["Coat Weight"].default_value = coat
    s.render.filepath = str(HERE / "out" / f"outdoor_coat{coat:g}.exr"); s.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    ch = read_exr_layers(s.render.filepath)
    m = np.rint(ch["ViewLayer.Object Index.X"]) == 1
    means.append(np.mean([ch[f"ViewLayer.Combined.{c}"][m].mean() for c in "RGB"]))
print(f"car pixels: coat 1 {means[0]:.4f}, coat 0 {means[1]:.4f}, ratio coat 0 / coat 1 {means[1] / means[0]:.3f}")
