"""STPM core renderer: time-dependent photon mapping (no bpy in here).

Entry points: :func:`stpm_core.render.render`, :mod:`stpm_core.scenefile`,
the ``stpm`` command (:mod:`stpm_core.cli`).  See docs/architecture.md.
"""
import os as _os

# numba's parallel kernels (ray casting, photon look-ups) open one thread region
# per batch; with spinning idle workers a loaded 2-core machine lost ~8x in
# throughput (docs/raycast.md).  Set before any numba pool starts; the user's own
# setting wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# numba caches each kernel against its own file only: after an edit of any kernel source, make
# every cached kernel stale before a kernel module defines its dispatchers (numba_probe).
from .numba_probe import invalidate_stale_caches as _invalidate_stale_caches  # noqa: E402

_invalidate_stale_caches()
