"""Locate ``stpm_core``: bundled inside the extension zip, or top-level in a checkout.

The built extension ships ``stpm_core`` as a sub-package of the add-on; a
checkout has it next to ``addon/``.  Either way the rest of the add-on reaches
the core only through this module, so one copy of each core module (and of its
exception classes) is used.  Before the core is imported, an installed extension points the
compiled-kernel cache at its user folder (:func:`_kernel_cache_folder`).
"""
from __future__ import annotations

import importlib
import os


def _kernel_cache_folder() -> str:
    """The extension's own user folder for compiled kernels ('' from a source checkout).

    An installed extension's folder may be read-only and is replaced by every update; Blender
    gives each extension a user folder that stays (``bpy.utils.extension_path_user``).  Handed to
    the core as ``STPM_KERNEL_CACHE`` before it is imported: numba chooses a kernel's cache folder
    when the kernel module is imported (``stpm_core.numba_probe.choose_cache_dir``).
    """
    if not (__package__ or "").startswith("bl_ext."):
        return ""
    try:
        import bpy
        return bpy.utils.extension_path_user(__package__, path="kernel-cache", create=True) or ""
    except (ImportError, AttributeError, ValueError, OSError):
        return ""


_KERNEL_CACHE = _kernel_cache_folder()
if _KERNEL_CACHE:
    os.environ.setdefault("STPM_KERNEL_CACHE", _KERNEL_CACHE)

try:  # the extension zip: <extension>/stpm_core
    from . import stpm_core as core  # type: ignore[attr-defined]
except ImportError:  # a source checkout: stpm_core is top-level
    import stpm_core as core


def sub(name: str):
    """Import the core sub-module ``name`` (e.g. ``'scene'``) from whichever copy is in use."""
    return importlib.import_module(f"{core.__name__}.{name}")


errors = sub("errors")
StpmError = errors.StpmError
RenderCancelled = errors.RenderCancelled
RenderSettings = sub("settings").RenderSettings
scene_model = sub("scene")
MotionTransform = sub("motion").MotionTransform
Shutter = sub("shutter").Shutter


def passes_table(denoise: bool = False, adaptive: bool = False) -> tuple:
    """The one table of render passes ``(name, channels, channel_ids)``: ``stpm_core.film.PASSES``
    (re-exported as ``stpm_core.render.PASSES``), with ``denoise`` plus the denoising passes
    (``film.passes_for``: Denoising Albedo, Denoising Normal, Noisy Image), with ``adaptive`` plus
    Sample Count (adaptive sampling)."""
    return tuple(sub("film").passes_for(bool(denoise), bool(adaptive)))


def render_function():
    """``stpm_core.render.render`` (imported lazily: it pulls in scipy / embreex)."""
    return sub("render").render


__all__ = ["core", "sub", "StpmError", "RenderCancelled", "RenderSettings", "scene_model",
           "MotionTransform", "Shutter", "passes_table", "render_function"]
