"""Render the pictures of docs/blender.md, "Denoising", through Blender as an artist would.

``blend_scenes/hdri_product.blend`` (rough copper, glass, an HDRI and an area light) rendered with
F12 (``bpy.ops.render.render``, the STPM engine and the compositor's STPM Denoise group):

* ``denoise_preview_raw_denoised_final.png``: the **Preview** preset with Denoise on -- its Noisy
  Image (left) and the compositor's denoised image (middle) -- next to the **Final** preset
  without denoising (right), Standard view transform;
* ``denoise_guides.png``: the Preview render's Denoising Albedo (left) and Denoising Normal
  (right, camera space shown as 0.5 + 0.5 n).

Prints each render's seconds and the HDR-FLIP of the noisy and the denoised image against the
Final one (``stpm_core.compare.metrics.flip_error``)::

    .venv/bin/python docs/make_denoise_image.py          # about 2 minutes on 2 cores
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def _layers(path) -> dict:
    """Every layer of Blender's multilayer EXR: name -> (H, W, C) float32, row 0 = top."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    out, sub = {}, 0
    while inp.seek_subimage(sub, 0):
        sp = inp.spec()
        px = inp.read_image(sub, 0, 0, sp.nchannels, "float")
        out[sp.getattribute("name")] = np.asarray(px, np.float32).reshape(sp.height, sp.width, sp.nchannels)
        sub += 1
    inp.close()
    return out


def _render(scene, path) -> tuple[dict, float]:
    import bpy
    s = scene.render.image_settings
    s.media_type, s.color_depth = "MULTI_LAYER_IMAGE", "32"
    scene.render.filepath, scene.render.use_file_extension = str(path), False
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return _layers(path), time.perf_counter() - t0


def main(argv=None) -> int:
    import bpy

    import addon
    from addon.presets import apply_preset
    from stpm_core.compare.metrics import flip_error
    from stpm_core.imageio import write_png

    addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "hdri_product.blend"))
    scene = bpy.context.scene
    scene.render.engine = "STPM"
    with tempfile.TemporaryDirectory(prefix="stpm_denoise_doc_") as tmp:
        apply_preset(scene.stpm, "PREVIEW")
        scene.stpm.denoise = True
        preview, t_preview = _render(scene, os.path.join(tmp, "preview.exr"))
        apply_preset(scene.stpm, "FINAL")
        scene.stpm.denoise = False
        final, t_final = _render(scene, os.path.join(tmp, "final.exr"))
    noisy = preview["ViewLayer.Noisy Image"][..., :3]
    denoised = preview["Composite.Combined"][..., :3]
    reference = final["ViewLayer.Combined"][..., :3]
    f_noisy, _ = flip_error(noisy, reference)
    f_denoised, _ = flip_error(denoised, reference)
    print(f"Preview with denoise {t_preview:.1f} s, Final {t_final:.1f} s")
    print(f"HDR-FLIP against Final: noisy {f_noisy:.4f}, denoised {f_denoised:.4f} "
          f"(ratio {f_denoised / f_noisy:.2f}); means {noisy.mean():.4f} / {denoised.mean():.4f} / {reference.mean():.4f}")
    images = os.path.join(ROOT, "docs", "images")
    out = os.path.join(images, "denoise_preview_raw_denoised_final.png")
    write_png(out, np.hstack([noisy, denoised, reference]))
    print("wrote", out)
    out = os.path.join(images, "denoise_guides.png")
    normal = 0.5 + 0.5 * preview["ViewLayer.Denoising Normal"][..., :3]
    write_png(out, np.hstack([preview["ViewLayer.Denoising Albedo"][..., :3], normal ** 2.2]))  # shown as stored
    print("wrote", out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
