"""Whether the compiled (numba) paths may be used in this process: one rule for every module.

``STPM_NO_NUMBA=1`` (any value but empty or 0) switches them off; otherwise
they are on when ``import numba`` works.  The modules with compiled kernels
(:mod:`stpm_core.shading_kernels`, :mod:`stpm_core.photons.kdtree`) keep
their own ``AVAILABLE`` flag from :func:`probe`, because each can also be
switched off later on its own (a compile failure).
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
    except Exception as exc:  # noqa: BLE001 -- any import failure: the numpy / scipy path
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
