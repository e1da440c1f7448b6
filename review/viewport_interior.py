"""The rendered viewport on review/out/interior.blend, driven as tests/test_addon_viewport.py drives it
(background bpy cannot draw: ViewportSession directly, a view through the scene camera at 320 x 180):
time to the first image and the first full pass, passes per second, the restart after an edit (the sofa
fabric's roughness) and after moving the wine glass, and the status lines.  Writes
review/out/viewport_interior.exr (the last image)."""
import sys, time
from pathlib import Path
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import numpy as np
import bpy, addon
addon.register()
from addon.viewport import ViewParams, ViewportSession

bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
scene = bpy.context.scene; scene.frame_set(12)
W, H = 320, 180
cam = scene.camera; dg = bpy.context.evaluated_depsgraph_get()
proj = cam.evaluated_get(dg).calc_matrix_camera(dg, x=W, y=H)
view = ViewParams.from_matrices(W, H, cam.matrix_world.inverted(), proj)
scene.stpm.preview_passes = 0
session = ViewportSession()
def handler(_s, depsgraph):
    if depsgraph.mode == "VIEWPORT":
        session.sync(depsgraph)
bpy.app.handlers.depsgraph_update_post.append(handler)
try:
    t0 = time.time()
    session.sync(bpy.context.evaluated_depsgraph_get(), view=view)
    assert session.wait(lambda s: s.images >= 1, timeout=600); t1 = time.time() - t0
    assert session.wait(lambda s: s.passes_done >= 1, timeout=600); t2 = time.time() - t0
    assert session.wait(lambda s: s.passes_done >= 4, timeout=900); t3 = time.time() - t0
    print(f"first image {t1:.2f} s ({session.image()[0].shape}), first full pass {t2:.2f} s, 4 passes {t3:.2f} s; "
          f"{session.status!r}; exports {session.cache.exports}, meshes {session.cache.mesh_conversions}")
    img = session.image()[0]
    import OpenImageIO as oiio
    o = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], 4, "float")); o.set_pixels(oiio.ROI(), np.ascontiguousarray(img[::-1]))
    o.write(str(HERE / "out" / "viewport_interior.exr"))
    # an edit: the fabric's roughness
    m, e = session.cache.mesh_conversions, session.cache.exports
    t0 = time.time(); bpy.data.materials["Fabric"].node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.6
    bpy.context.view_layer.update()
    v = session.image()[1]
    assert session.wait(lambda s: s.image()[1] > v, timeout=600)
    print(f"material edit: new image after {time.time() - t0:.2f} s, exports +{session.cache.exports - e}, meshes +{session.cache.mesh_conversions - m}")
    # the glass moves (its turntable)
    m, e = session.cache.mesh_conversions, session.cache.exports
    t0 = time.time(); bpy.data.objects["Turntable"].location.x += 0.1; bpy.context.view_layer.update()
    v = session.image()[1]
    assert session.wait(lambda s: s.image()[1] > v, timeout=600)
    print(f"object move: new image after {time.time() - t0:.2f} s, exports +{session.cache.exports - e}, meshes +{session.cache.mesh_conversions - m}")
finally:
    print("stopped", session.stop())
