"""Cycles as the reference: render one bpy scene with Cycles and with STPM, compare blocks.

Both renderers see the same scene (STPM through the add-on's exporter).  Comparisons are
Z-tests on block means in the manner of Mitsuba's render tests: each renderer renders K seeds,
every B x B block's mean gets a mean and a variance over the seeds, and

    z_b = (mean_stpm_b - mean_cycles_b) / sqrt(var_stpm_b / K + var_cycles_b / K + floor_b^2)

must stay below ``z_max`` in every block.  ``floor_b`` (a small fraction of the block's level)
keeps noise-free blocks (a flat texel, a constant background) from turning rounding-level
differences into large z.  Direct-only renders: Cycles with ``max_bounces = 0``; STPM without
photons (Combined = Emit + Direct) -- which is direct light only for diffuse materials: STPM's
camera paths still go on through glossy and glass lobes unless their bounce budgets are 0 too
(``glossy_bounces = transmission_bounces = diffuse_bounces = 0``; a review measured a metal +33 %
and a floor +1.6-3 % over Cycles' direct light without them).

Imported by the Cycles comparison tests; needs bpy and OpenImageIO.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["render_cycles", "render_stpm", "block_ztest", "ZResult", "lit_variance_ratio"]


def _read_exr_rgb(path) -> np.ndarray:
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    px = inp.read_image(0, 0, 0, spec.nchannels, "float").reshape(spec.height, spec.width, spec.nchannels)
    inp.close()
    return np.asarray(px[..., :3], np.float64)


def render_cycles(scene, tmp_path, samples: int = 64, seeds=(0, 1, 2, 3), max_bounces: int = 0) -> np.ndarray:
    """(K, H, W, 3) linear RGB of Cycles (CPU, no denoising, no adaptive sampling), one image per seed."""
    cy = _cycles_setup(scene, samples)
    cy.max_bounces = max_bounces
    cy.diffuse_bounces = cy.glossy_bounces = cy.transmission_bounces = min(max_bounces, 12)
    cy.caustics_reflective = cy.caustics_refractive = max_bounces > 0
    return _cycles_seeds(scene, tmp_path, seeds, "cycles")


def _cycles_setup(scene, samples: int):
    """Cycles on the CPU at ``samples``, no denoising, adaptive sampling or clamping, EXR output;
    returns scene.cycles for the caller's bounce settings."""
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", samples, False, False
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    if hasattr(scene.render.image_settings, "media_type"):
        scene.render.image_settings.media_type = "IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    return cy


def _cycles_seeds(scene, tmp_path, seeds, prefix: str) -> np.ndarray:
    """(K, H, W, 3): one render per seed, read back from ``tmp_path/<prefix>_<seed>.exr``."""
    import bpy
    out = []
    for s in seeds:
        scene.cycles.seed = int(s)
        path = tmp_path / f"{prefix}_{s}.exr"
        scene.render.filepath = str(path)
        bpy.ops.render.render(write_still=True)
        out.append(_read_exr_rgb(path))
    return np.stack(out)


def render_stpm(scene, samples: int = 64, seeds=(0, 1, 2, 3), **settings):
    """((K, H, W, 3) Combined linear RGB, the last RenderResult) of STPM on the exported scene."""
    from addon.export import export_scene
    import bpy
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    bl = bpy.context.scene
    core, _warnings = export_scene(bpy.context.evaluated_depsgraph_get(),
                                   lambda f, sub: bl.frame_set(f, subframe=sub))[:2]
    kw = dict(photons_caustic=0, photons_global=0)
    kw.update(settings)
    out, res = [], None
    for s in seeds:
        res = render(core, RenderSettings(samples=samples, seed=int(s), **kw))
        out.append(np.asarray(res.passes["Combined"][..., :3], np.float64))
    return np.stack(out), res


@dataclass
class ZResult:
    z: np.ndarray            # (by, bx) block z values
    stpm: np.ndarray         # (by, bx) block means (over seeds)
    cycles: np.ndarray
    mean_ratio: float        # mean(STPM) / mean(Cycles) over the image

    @property
    def z_abs_max(self) -> float:
        return float(np.max(np.abs(self.z)))

    def summary(self) -> str:
        return (f"|z| max {self.z_abs_max:.2f}, mean ratio {self.mean_ratio:.4f}, blocks {self.z.size}, "
                f"|z|>3: {int(np.sum(np.abs(self.z) > 3))}")


def block_ztest(a: np.ndarray, b: np.ndarray, block: int = 8, floor: float = 0.002) -> ZResult:
    """Z-test of (K, H, W, 3) image stacks a (STPM) and b (Cycles) on block x block blocks of the
    channel-mean image; floor: relative level added in quadrature to the standard error."""
    def blocks(x):
        K, H, W, _ = x.shape
        y = x.mean(axis=-1)[:, :H // block * block, :W // block * block]
        return y.reshape(K, H // block, block, W // block, block).mean(axis=(2, 4))
    A, B = blocks(a), blocks(b)
    ma, mb = A.mean(axis=0), B.mean(axis=0)
    va, vb = A.var(axis=0, ddof=1), B.var(axis=0, ddof=1)
    se = np.sqrt(va / A.shape[0] + vb / B.shape[0] + (floor * 0.5 * (ma + mb)) ** 2 + 1e-12)
    return ZResult(z=(ma - mb) / se, stpm=ma, cycles=mb, mean_ratio=float(a.mean() / max(b.mean(), 1e-300)))


def render_cycles_paths(scene, tmp_path, samples: int = 64, seeds=(0, 1, 2, 3), *, diffuse_bounces: int = 1,
                        glossy_bounces: int = 8, transmission_bounces: int = 8, caustics: bool = True,
                        blur_glossy: float = 0.0) -> np.ndarray:
    """(K, H, W, 3) linear RGB of Cycles with a bounce limit per kind (``render_cycles`` gives every kind
    the same count): e.g. one diffuse bounce with long glass chains for caustics.  ``max_bounces`` is
    the sum of the three, so only the per-kind limits bind.  ``blur_glossy`` is Cycles' Filter Glossy
    (default 1.0 there, which blurs caustics: 0 here).  CPU, no denoising, no adaptive sampling, no
    clamping, as ``render_cycles``."""
    cy = _cycles_setup(scene, samples)
    cy.diffuse_bounces, cy.glossy_bounces = diffuse_bounces, glossy_bounces
    cy.transmission_bounces = transmission_bounces
    cy.max_bounces = diffuse_bounces + glossy_bounces + transmission_bounces
    cy.caustics_reflective = cy.caustics_refractive = bool(caustics)
    cy.blur_glossy = float(blur_glossy)
    return _cycles_seeds(scene, tmp_path, seeds, "cycles_paths")


def lit_variance_ratio(stpm: np.ndarray, cyc: np.ndarray, lit: float = 0.05) -> tuple[float, int]:
    """(median over lit pixels of the per-pixel variance over seeds STPM / Cycles, lit pixel count) of
    (K, H, W, 3) stacks (channel means).  Lit: Cycles' mean above ``lit`` times its 90th percentile
    (an emitter the camera sees is far brighter than any wall, and has no noise)."""
    s, c = stpm.mean(axis=-1), cyc.mean(axis=-1)
    m = c.mean(axis=0)
    sel = m > lit * np.percentile(m, 90)
    ratio = s.var(axis=0, ddof=1)[sel] / np.maximum(c.var(axis=0, ddof=1)[sel], 1e-12)
    return float(np.median(ratio)), int(sel.sum())
