"""The photon record: 36 bytes per stored photon.

Layout (numpy structured dtype :data:`PHOTON_DTYPE`, little-endian, packed)::

    offset  bytes  field      type          meaning
    0       12     position   float32 x 3   hit point relative to the map's origin (scene units, m)
    12       4     time       float32       normalised shutter time t in [0, 1] of the photon's path
    16      12     power      float32 x 3   RGB flux Phi carried by the photon (W)
    28       4     wi_oct     int16 x 2     incoming direction, octahedral-packed (see below)
    32       4     ng_oct     int16 x 2     the surface's geometric normal, on the side of wi, octahedral
                                            (NO_NORMAL: none stored)
    ----    36

Positions are stored relative to the map's ``origin`` (float64, the centre of
the scene's bounds: :func:`photon_origin`), so float32 keeps its ~1e-7
relative precision over the scene's own extent even for a scene placed 1e5
units from the world origin (world float32 would quantise it to ~8 mm).

``wi`` is the unit direction from the surface back toward where the photon
came from (it points away from the surface on the side the photon arrived
on), so a query with shading normal ``ns`` counts the photon when
``dot(ns, wi) > 0``.

Octahedral packing (Meyer et al. 2010, "On floating-point normal vectors"):
project the unit vector onto the octahedron |x|+|y|+|z| = 1, fold the lower
half (z < 0) over the diagonals onto the square [-1, 1]^2 and quantise each
coordinate to int16 (step 1/32767).  The worst-case angular error is about
6e-5 rad, far below anything the side test can notice.

``ng_oct``: the unit geometric normal of the surface the photon was stored on, turned to the side
of wi (``dot(ng, wi) > 0``), so a look-up can reject photons of a surface facing another way than
its own (an open outer corner's face behind a wall: docs/photon-mapping.md, "Tangent slab",
"Photon normals").  Records made without normals hold ``NO_NORMAL`` (-32768, a code the encoder
never writes) in both codes: such photons pass the normal test.  The look-ups read it through
:func:`normal_codes`, one float32 per photon (FlatTree's spare column).

The parity of ``wi_oct[0]`` carries one flag, :func:`delta_only`: odd = the photon reached its
surface through delta lobes alone (L S+ D; the caustic map's photons a rough lobe of the camera
vertex may read, docs/rendering.md "Path partition").  ``make_records(..., delta_only=...)`` sets
it by moving the first code by at most one step (3e-5) toward zero; records made without it keep
their rounding (and read as flagged where it happens to be odd: only the caustic map's records,
which the tracer always flags, are read for it).
"""
from __future__ import annotations

import numpy as np

__all__ = ["PHOTON_DTYPE", "BYTES_PER_PHOTON", "make_records", "photon_origin", "oct_encode", "oct_decode",
           "delta_only", "NO_NORMAL", "normal_codes", "decode_normal_codes"]

PHOTON_DTYPE = np.dtype([
    ("position", "<f4", (3,)),
    ("time", "<f4"),
    ("power", "<f4", (3,)),
    ("wi_oct", "<i2", (2,)),
    ("ng_oct", "<i2", (2,)),
])
BYTES_PER_PHOTON = PHOTON_DTYPE.itemsize
assert BYTES_PER_PHOTON == 36
NO_NORMAL = -32768           # ng_oct of a record without a stored normal (oct_encode writes >= -32767)

_Q = 32767.0  # int16 quantisation scale of the octahedral square


def _sign_nz(x: np.ndarray) -> np.ndarray:
    """sign(x) with sign(0) = +1, so the fold is defined on the axes."""
    return np.where(x >= 0.0, 1.0, -1.0)


def oct_encode(w: np.ndarray) -> np.ndarray:
    """Unit directions w (n, 3) -> octahedral codes (n, 2) int16."""
    w = np.asarray(w, dtype=np.float64)
    l1 = np.maximum(np.abs(w).sum(axis=-1, keepdims=True), 1e-30)
    v = w / l1
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    # Fold the lower hemisphere over the square's diagonals
    lower = z < 0.0
    fx = np.where(lower, (1.0 - np.abs(y)) * _sign_nz(x), x)
    fy = np.where(lower, (1.0 - np.abs(x)) * _sign_nz(y), y)
    q = np.stack([fx, fy], axis=-1)
    return np.clip(np.rint(q * _Q), -_Q, _Q).astype(np.int16)


def oct_decode(code: np.ndarray) -> np.ndarray:
    """Octahedral codes (..., 2) int16 -> unit directions (..., 3) float32."""
    q = np.asarray(code, dtype=np.float32) / np.float32(_Q)
    x, y = q[..., 0], q[..., 1]
    z = 1.0 - np.abs(x) - np.abs(y)
    # Unfold the lower hemisphere
    lower = z < 0.0
    ux = np.where(lower, (1.0 - np.abs(y)) * np.where(x >= 0, 1.0, -1.0), x)
    uy = np.where(lower, (1.0 - np.abs(x)) * np.where(y >= 0, 1.0, -1.0), y)
    w = np.stack([ux, uy, z], axis=-1).astype(np.float32)
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


_NQ = 2047                   # normal_codes: 2 NQ + 1 = 4095 levels per octahedral axis (0 exact)


def normal_codes(records: np.ndarray) -> np.ndarray:
    """(n,) float32: each record's ng_oct requantised to 12 bits an axis and packed into one float32
    integer, 1 + (iu * 4096 + iv) with iu, iv in [0, 2 NQ] (exact below 2^24); 0 = no normal.

    What the look-ups read (``estimators.PhotonMap``'s packed column 7, ``kdtree._facing``): one float
    of a 32-byte row.  12 bits an axis: about 1e-3 rad, nothing next to the test's 60 degrees."""
    c = np.asarray(records["ng_oct"], np.int32)
    none = (c[:, 0] == NO_NORMAL) | (c[:, 1] == NO_NORMAL)
    i = np.rint((c.astype(np.float64) / _Q) * _NQ).astype(np.int64) + _NQ
    code = 1 + i[:, 0] * 4096 + i[:, 1]
    return np.where(none, 0, code).astype(np.float32)


def decode_normal_codes(code: np.ndarray) -> np.ndarray:
    """normal_codes (n,) -> (n, 3) float64 unit normals (zeros where 0: no normal).  The numpy copy of
    ``kdtree._facing``'s decoding (the scipy look-ups, tests)."""
    k = np.asarray(code, np.float64).astype(np.int64) - 1
    u = (k // 4096 - _NQ) / _NQ
    v = (k % 4096 - _NQ) / _NQ
    z = 1.0 - np.abs(u) - np.abs(v)
    lower = z < 0.0
    x = np.where(lower, (1.0 - np.abs(v)) * _sign_nz(u), u)
    y = np.where(lower, (1.0 - np.abs(u)) * _sign_nz(v), v)
    n = np.stack([x, y, z], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.where((k < 0)[:, None], 0.0, n)


def photon_origin(scene) -> np.ndarray:
    """(3,) float64 origin of the scene's photon records: the centre of its bounds over the shutter."""
    lo, hi = scene.bounds()
    return 0.5 * (np.asarray(lo, np.float64) + np.asarray(hi, np.float64))


def delta_only(records: np.ndarray) -> np.ndarray:
    """(n,) bool: the photon's path bounced off delta lobes only (the parity flag of ``wi_oct[0]``)."""
    return (np.asarray(records["wi_oct"][:, 0], np.int32) & 1) == 1


def _set_parity(code: np.ndarray, flag: np.ndarray) -> None:
    """Make code (n,) int16 odd where flag, even elsewhere, moving it by one step toward zero."""
    c = code.astype(np.int32)
    wrong = (c & 1) != np.asarray(flag, np.int32)
    c = np.where(wrong, c - np.where(c > 0, 1, -1), c)
    code[:] = c.astype(np.int16)


def make_records(position: np.ndarray, wi: np.ndarray, power: np.ndarray, time: np.ndarray,
                 origin: np.ndarray | None = None, delta_only: np.ndarray | None = None,
                 ng: np.ndarray | None = None) -> np.ndarray:
    """Pack photons into records.

    Parameters
    ----------
    position : (n, 3) world hit points (m), float64.
    origin : (3,) float64 subtracted before the float32 cast (None = world origin).
    wi : (n, 3) unit incoming directions (pointing away from the surface).
    power : (n, 3) RGB flux (W).
    time : (n,) normalised shutter times.
    delta_only : (n,) bool or None: the flag of :func:`delta_only` (None: not set).
    ng : (n, 3) unit geometric normals of the surfaces hit (either side: turned here to the side of
        wi), or None: no normal (``NO_NORMAL``; such photons pass the look-ups' normal test).

    Returns
    -------
    (n,) array of :data:`PHOTON_DTYPE`.
    """
    n = int(np.asarray(time).shape[0])
    rec = np.empty(n, dtype=PHOTON_DTYPE)
    if n:
        rec["position"] = position if origin is None else np.asarray(position, np.float64) - origin
        rec["time"] = time
        rec["power"] = power
        rec["wi_oct"] = oct_encode(wi)
        if ng is None:
            rec["ng_oct"] = NO_NORMAL
        else:
            ng = np.asarray(ng, np.float64).reshape(n, 3)
            flip = np.einsum("ij,ij->i", ng, np.asarray(wi, np.float64).reshape(n, 3)) < 0.0
            rec["ng_oct"] = oct_encode(np.where(flip[:, None], -ng, ng))
            rec["ng_oct"][~(np.abs(ng).sum(axis=1) > 0.0)] = NO_NORMAL      # (a zero or nan normal: none)
        if delta_only is not None:
            _set_parity(rec["wi_oct"][:, 0], np.broadcast_to(np.asarray(delta_only, bool), (n,)))
    return rec
