"""Whether the compiled (numba) paths may be used in this process: one rule for every module.

``STPM_NO_NUMBA=1`` (any value but empty or 0) switches them off; otherwise
they are on when ``import numba`` works.  The result is ``AVAILABLE`` (and
``IMPORT_ERROR``, why not), and ``njit``: numba's decorator, or a placeholder
that leaves functions uncompiled when numba is off, so that the kernel modules
still import.

* Shading: every module of :mod:`stpm_core.kernels` with kernels (closure,
  bsdf, lights, emission, sampling, paths, photon_paths) imports ``njit`` from
  here, and :func:`stpm_core.kernels.require` turns ``AVAILABLE`` False (or a
  numba that cannot compile) into the one-line
  :class:`stpm_core.kernels.KernelsUnavailable`: a render stops, there is no
  numpy fallback for shading.
* Photon look-ups: :mod:`stpm_core.photons.kdtree` keeps its own
  ``AVAILABLE`` flag from :func:`probe`, because it can also be switched off
  later on its own (a compile failure); without numba (or with
  ``STPM_NO_NUMBA``) ``PhotonMap`` uses scipy's cKDTree.
* Ray casting (:mod:`stpm_core.raycast`) checks ``import numba`` itself when
  choosing between its embree / numba / numpy backends (``STPM_NO_NUMBA``
  does not switch those off).
"""
from __future__ import annotations

import os

__all__ = ["probe", "njit", "AVAILABLE", "IMPORT_ERROR"]


def probe() -> tuple[bool, str]:
    """(available, reason when not): numba importable and not disabled by STPM_NO_NUMBA."""
    if os.environ.get("STPM_NO_NUMBA", "") not in ("", "0"):
        return False, "disabled by STPM_NO_NUMBA"
    try:
        import numba  # noqa: F401
    except Exception as exc:  # noqa: BLE001 -- any import failure: KernelsUnavailable for shading, scipy for the kd-tree
        return False, f"{type(exc).__name__}: {exc}"
    return True, ""


AVAILABLE, IMPORT_ERROR = probe()

if AVAILABLE:
    from numba import njit  # noqa: F401  (the compiled kernels' decorator)
else:                                          # pragma: no cover - depends on the platform
    def njit(*args, **kwargs):                 # noqa: D103 -- placeholder so kernel modules import
        if len(args) == 1 and callable(args[0]) and not kwargs:
            return args[0]

        def wrap(f):
            return f
        return wrap
