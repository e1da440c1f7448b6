"""Time-stamped photon maps and the three irradiance estimates (STANDARD, TEMPORAL, KD4D).

Modules: :mod:`.record` (the 32-byte photon record), :mod:`.trace` (photon
paths, one shutter time each), :mod:`.estimators` (the estimates and their
normalisations), :mod:`.kdtree` (compiled look-ups, numba; scipy fallback),
:mod:`.timescale` (KD4D's automatic s), :mod:`.maps` (build_photon_maps /
PhotonMaps).  See docs/photon-mapping.md.
"""
from .estimators import PhotonMap
from .maps import KINDS, PhotonMaps, build_photon_maps
from .record import BYTES_PER_PHOTON, PHOTON_DTYPE

__all__ = ["build_photon_maps", "PhotonMaps", "PhotonMap", "PHOTON_DTYPE", "BYTES_PER_PHOTON", "KINDS"]
