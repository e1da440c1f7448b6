"""Partial results of progressive renders: one machine's passes, written so another can merge them.

    stpm render shot.blend --method progressive --pass-offset 0  --passes 32 -o part_a.exr
    stpm render shot.blend --method progressive --pass-offset 32 --passes 32 -o part_b.exr
    stpm merge part_a.exr part_b.exr -o shot.exr           # = one render of passes 1..64

A partial result is a multilayer EXR that any viewer opens (the mean of its
passes, Blender's channel names) with the exact float64 sums of its passes
beside it, and a JSON header attribute ``stpm:partial``:

* ``format`` "stpm-partial", ``version`` 2;
* ``pass_first``, ``pass_end``: the passes it holds, ``[first, end)`` (1-based; whole
  rounds of time strata: first - 1 and end - 1 are round ends, :mod:`stpm_core.strata`);
* ``n_even``, ``n_odd``: how many even / odd pass indices (for the noise estimate);
* ``seed``, ``scene_hash`` (:func:`scene_hash`), ``scene_fingerprint`` (:func:`scene_fingerprint`:
  per array of the scene file a digest and float sums, so that :func:`merge` can tell float
  rounding from an edit), ``settings_hash``
  (:func:`settings_hash`: every setting that changes a pass's pixels), ``resolution``,
  ``working_space`` (the colour space the passes are in: ``stpm_core.colorspaces``);
* ``region``: the Render Region whose pixels alone the passes traced, ``[x0, y0, x1, y1]`` pixels
  with rows from the top (:attr:`PassSums.window`; the sums are 0 outside it), or null for the
  whole frame (absent in partials written before regions were traced alone: they hold the whole
  frame); ``region_crop``: the scene's *Crop to Render Region*, which ``stpm merge`` applies.

Float64 in EXR: each float64 value x is stored as three float32 channels
hi = f32(x), mid = f32(x - hi), lo = f32(x - hi - mid); each difference is exact in
float64 and hi + mid + lo = x exactly (for |x| within float32's range), so the
sums survive the file bit for bit.  Layers ``STPMSum<Pass>Hi`` / ``Mid`` / ``Lo``
hold pass ``<Pass>``'s sum with that pass's channels; ``STPMSumEven*`` / ``STPMSumOdd*``
the half sums of Combined RGB.

Reading checks everything (a partial is untrusted input like any file): the
header's types and ranges, every layer present with the right shape, every
value finite; :func:`merge` refuses gaps, overlaps and partials of another
scene, seed, settings or Render Region.  Sums of disjoint pass ranges add in float64 (another
association than one process's running sum: equal to about 1e-16 relative, so
the float32 image is bit-equal but for a rare last-bit tie).
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from .errors import StpmError
from .progressive import PassSums
from .strata import is_round_end

__all__ = ["PARTIAL_FORMAT", "PARTIAL_VERSION", "scene_hash", "scene_fingerprint", "fingerprint_difference",
           "settings_hash", "write_partial", "read_partial",
           "merge", "split64", "join64"]

PARTIAL_FORMAT = "stpm-partial"
PARTIAL_VERSION = 2          # 2: passes in pairs of one time stratum, whole rounds only (stpm_core.strata)
SUM_PREFIX = "STPMSum"
_PARTS = ("Hi", "Mid", "Lo")
# Settings that do not change a pass's pixels (how many passes, where to stop, threads)
_NOT_HASHED = ("passes", "pass_offset", "time_limit", "noise_threshold", "threads")


def split64(x: np.ndarray) -> np.ndarray:
    """float64 (...,) -> float32 (..., 3) (hi, mid, lo) with hi + mid + lo == x exactly (|x| < 3e38)."""
    x = np.asarray(x, dtype=np.float64)
    hi = x.astype(np.float32)
    r = x - hi.astype(np.float64)
    mid = r.astype(np.float32)
    lo = (r - mid.astype(np.float64)).astype(np.float32)
    return np.stack([hi, mid, lo], axis=-1)


def join64(parts: np.ndarray) -> np.ndarray:
    """Inverse of :func:`split64`: float32 (..., 3) -> float64 (...,)."""
    p = np.asarray(parts, dtype=np.float64)
    return (p[..., 0] + p[..., 1]) + p[..., 2]


# Scene metadata that says where a scene came from, not what it looks like: left out of the hashes,
# so that partials of one frame rendered from the .blend at different paths merge (a farm's
# workers mount the project at different paths; `stpm render shot.blend` run from another folder).
# ``source`` is the .blend's path as typed; ``warnings`` name missing files by their resolved paths.
# (Second artist review: one .blend copied under another name, both partials refused as "partials
# of different scenes".)
UNHASHED_METADATA = ("source", "warnings", "name", "description")


def _hashed_header(header: dict) -> str:
    """The scene file's header as JSON for hashing, without :data:`UNHASHED_METADATA`."""
    meta = header.get("metadata") if isinstance(header, dict) else None
    if isinstance(meta, dict):
        header = {**header, "metadata": {k: v for k, v in meta.items() if k not in UNHASHED_METADATA}}
    return json.dumps(header, sort_keys=True, default=str)


def scene_hash(scene) -> str:
    """SHA-256 of the scene as the scene file stores it (header JSON without
    :data:`UNHASHED_METADATA`, and every array's bytes)."""
    from .scenefile import scene_to_arrays
    header, arrays = scene_to_arrays(scene)
    h = hashlib.sha256(_hashed_header(header).encode())
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}|{a.dtype.str}|{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


# Blender's evaluated meshes are not bit-reproducible from run to run: the Bevel modifier's UVs
# differ in the last bit or two (review/make_bevel_min.py: a new scene_hash in every process), so
# two machines exporting one .blend frame get scenes whose exact hashes differ.  The fingerprint
# keeps, per float array, its sums under three fixed weightings and its sum of |x|; merge accepts
# arrays whose sums agree to _ULP_TOL float32 rounding units of sum |x| (a last-bit difference of
# every element moves a sum by at most 2^-23 sum |x|) and names any other difference as an edit.
_ULP_TOL = 8.0 * 2.0 ** -23
_SKETCH_LEN = 4              # sum x, sum x * ramp, sum x * hash weights, sum |x|


def _sketch(a: np.ndarray) -> list[float]:
    """Float64 sums of a float array (any shape; flattened): [sum x, sum x r_i, sum x h_i, sum |x|].

    r_i = i / n (a ramp) and h_i in [-0.5, 0.5) from a multiplicative hash of i, so that an edit
    which keeps sum x (a vertex moved one way, another the other way) still moves a sum.
    """
    x = np.asarray(a, dtype=np.float64).ravel()
    n = x.size
    if n == 0:
        return [0.0] * _SKETCH_LEN
    i = np.arange(n, dtype=np.uint64)
    ramp = (i.astype(np.float64) + 0.5) / n
    h = ((i * np.uint64(2654435761)) & np.uint64(0xFFFFFFFF)).astype(np.float64) / 2.0 ** 32 - 0.5
    return [float(x.sum()), float(x @ ramp), float(x @ h), float(np.abs(x).sum())]


def scene_fingerprint(scene) -> dict:
    """What :func:`merge` compares when two partials' ``scene_hash`` differ.

    ``{"header": SHA-256 of the scene file's header JSON (as :func:`scene_hash`), "arrays": {key: [digest (16 hex), kind,
    sketch]}}`` where kind is "f" for a float array (sketch: :func:`_sketch`, 4 floats) and "x" for
    any other (sketch empty: it must match exactly).
    """
    from .scenefile import scene_to_arrays
    header, arrays = scene_to_arrays(scene)
    out = {}
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h = hashlib.sha256(f"{key}|{a.dtype.str}|{a.shape}".encode())
        h.update(a.tobytes())
        is_float = a.dtype.kind == "f" and np.all(np.isfinite(a))
        out[key] = [h.hexdigest()[:16], "f" if is_float else "x", _sketch(a) if is_float else []]
    return {"header": hashlib.sha256(_hashed_header(header).encode()).hexdigest(), "arrays": out}


def _check_fingerprint(fp, path) -> None:
    """Raise StpmError unless ``fp`` has :func:`scene_fingerprint`'s shape (untrusted input)."""
    ok = (isinstance(fp, dict) and isinstance(fp.get("header"), str) and len(fp["header"]) == 64
          and isinstance(fp.get("arrays"), dict))
    if ok:
        for k, v in fp["arrays"].items():
            if not (isinstance(k, str) and isinstance(v, list) and len(v) == 3 and isinstance(v[0], str)
                    and v[1] in ("f", "x") and isinstance(v[2], list)
                    and len(v[2]) == (_SKETCH_LEN if v[1] == "f" else 0)
                    and all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)
                            for x in v[2])):
                ok = False
                break
    if not ok:
        raise StpmError(f"{path}: partial result header field 'scene_fingerprint' is invalid")


def fingerprint_difference(a: dict | None, b: dict | None) -> str | None:
    """None when two fingerprints describe one scene up to float rounding, else what differs (text).

    Float arrays may differ by rounding: each of their sums within _ULP_TOL * sum |x| (the larger
    of the two) of the other's; everything else (the header, array names, shapes, dtypes, integer
    arrays) must be identical.  A missing fingerprint (an older partial) is a difference.
    """
    if a is None or b is None:
        return "a partial without a scene fingerprint"
    if a["header"] != b["header"]:
        return "the scene description (objects, materials, camera, lights or settings)"
    if set(a["arrays"]) != set(b["arrays"]):
        return "the scene's arrays (" + ", ".join(sorted(set(a["arrays"]) ^ set(b["arrays"])))[:80] + ")"
    for key in sorted(a["arrays"]):
        (da, ka, sa), (db, kb, sb) = a["arrays"][key], b["arrays"][key]
        if da == db:
            continue
        if ka != "f" or kb != "f":
            return f"array {key}"
        tol = _ULP_TOL * max(abs(sa[-1]), abs(sb[-1]))
        if any(abs(x - y) > tol for x, y in zip(sa, sb)):
            return f"array {key}"
    return None


def settings_hash(settings) -> str:
    """SHA-256 of the settings that change a pass's pixels (not passes, pass_offset, stops, threads)."""
    d = {k: v for k, v in settings.to_dict().items() if k not in _NOT_HASHED}
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()


def write_partial(path, sums: PassSums, *, seed: int, scene_digest: str, settings_digest: str,
                  metadata: dict | None = None, atomic: bool = True, working: str = "REC709",
                  scene_print: dict | None = None, crop: bool = False) -> Path:
    """Write ``sums`` (its mean as the visible passes, the exact sums beside) to the EXR ``path``;
    ``sums.window`` (a Render Region) and ``crop`` (Crop to Render Region) go into the header."""
    from .imageio import write_exr
    if sums.count == 0:
        raise StpmError("no pass to write")
    passes = dict(sums.image())
    H, W = next(iter(passes.values())).shape[:2]
    halves = (("Even", sums.even), ("Odd", sums.odd))
    for name, s in list(sums.sums.items()) + [(n, np.zeros((H, W, 3)) if s is None else s) for n, s in halves]:
        parts = split64(s)
        for k, part in enumerate(_PARTS):
            passes[SUM_PREFIX + name + part] = parts[..., k]
    head = {"format": PARTIAL_FORMAT, "version": PARTIAL_VERSION, "pass_first": sums.first, "pass_end": sums.end,
            "n_even": sums.n_even, "n_odd": sums.n_odd, "seed": int(seed), "scene_hash": scene_digest,
            "settings_hash": settings_digest, "resolution": [int(W), int(H)],
            "passes": sorted(sums.sums), "working_space": working,
            "region": None if sums.window is None else [int(v) for v in sums.window], "region_crop": bool(crop)}
    if scene_print is not None:
        head["scene_fingerprint"] = scene_print
    meta = dict(metadata or {})
    meta["stpm:partial"] = json.dumps(head)
    return write_exr(path, passes, meta, atomic=atomic, working=working)


def _field(head: dict, key: str, kind, path, lo=None):
    v = head.get(key)
    ok = isinstance(v, kind) and not isinstance(v, bool)
    if ok and lo is not None:
        ok = v >= lo
    if not ok:
        raise StpmError(f"{path}: partial result header field {key!r} is invalid ({v!r:.60})")
    return v


def read_partial(path) -> tuple[PassSums, dict]:
    """(PassSums, header) of a partial result; StpmError naming the file and the problem."""
    from .imageio import read_exr
    path = Path(path)
    if not path.exists():
        raise StpmError(f"partial result not found: {path}")
    data = read_exr(path)
    text = data["_metadata"].get("stpm:partial")
    if not isinstance(text, str):
        raise StpmError(f"{path}: not a partial result (no stpm:partial header; render it with --pass-offset)")
    try:
        head = json.loads(text)
    except (ValueError, RecursionError):
        raise StpmError(f"{path}: the stpm:partial header is not valid JSON") from None
    if not isinstance(head, dict) or head.get("format") != PARTIAL_FORMAT:
        raise StpmError(f"{path}: not an STPM partial result (format {head.get('format') if isinstance(head, dict) else None!r:.40})")
    version = _field(head, "version", int, path, 1)
    if version > PARTIAL_VERSION:
        raise StpmError(f"{path}: partial result version {version} is newer than this STPM reads ({PARTIAL_VERSION})")
    if version < PARTIAL_VERSION:
        raise StpmError(f"{path}: partial result version {version} comes from an older STPM whose passes sample "
                        "the shutter differently: render it again")
    first = _field(head, "pass_first", int, path, 1)
    end = _field(head, "pass_end", int, path, first + 1)
    n_even = _field(head, "n_even", int, path, 0)
    n_odd = _field(head, "n_odd", int, path, 0)
    expect_even = sum(1 for i in range(first, end) if i % 2 == 0) if end - first < 1 << 24 else -1
    if end - first >= 1 << 24 or n_even != expect_even or n_even + n_odd != end - first:
        raise StpmError(f"{path}: partial result pass counts do not match its range {first}..{end - 1}")
    if not (is_round_end(first - 1) and is_round_end(end - 1)):
        raise StpmError(f"{path}: partial result range {first}..{end - 1} does not hold whole rounds of time strata")
    _field(head, "seed", int, path, 0)
    for key in ("scene_hash", "settings_hash"):
        v = _field(head, key, str, path)
        if len(v) != 64 or any(c not in "0123456789abcdef" for c in v):
            raise StpmError(f"{path}: partial result header field {key!r} is not a SHA-256 digest")
    res = head.get("resolution")
    names = head.get("passes")
    if not (isinstance(res, list) and len(res) == 2 and all(isinstance(x, int) and not isinstance(x, bool) and x > 0
                                                            for x in res)):
        raise StpmError(f"{path}: partial result header field 'resolution' is invalid")
    if not (isinstance(names, list) and names and all(isinstance(n, str) for n in names) and "Combined" in names):
        raise StpmError(f"{path}: partial result header field 'passes' is invalid")
    from .colorspaces import WORKING_SPACES
    working = head.get("working_space", "REC709")       # absent in a partial of a Rec.709 scene
    if not isinstance(working, str) or working not in WORKING_SPACES:
        raise StpmError(f"{path}: partial result header field 'working_space' is invalid ({working!r:.40})")
    head["working_space"] = working
    if "scene_fingerprint" in head:      # absent in partials written before it was added
        _check_fingerprint(head["scene_fingerprint"], path)
    W, H = res
    region = head.get("region")          # absent in partials written before regions: the whole frame
    if region is not None and not (isinstance(region, list) and len(region) == 4
                                   and all(isinstance(v, int) and not isinstance(v, bool) for v in region)
                                   and 0 <= region[0] < region[2] <= W and 0 <= region[1] < region[3] <= H):
        raise StpmError(f"{path}: partial result header field 'region' is invalid ({region!r:.60})")
    head["region"] = region
    head["region_crop"] = head.get("region_crop", False)
    if not isinstance(head["region_crop"], bool):
        raise StpmError(f"{path}: partial result header field 'region_crop' is invalid")
    # where it came from (the render's settings, plan, scene and frame), carried into a merged EXR
    head["provenance"] = {k: v for k, v in data["_metadata"].items()
                          if k in ("stpm:settings", "stpm:plan", "stpm:scene", "stpm:frame") and isinstance(v, str)}
    sums = PassSums(first, window=region)
    sums.end = sums.next = end
    sums.n_even, sums.n_odd = n_even, n_odd

    def layer(name, channels):
        parts = []
        for part in _PARTS:
            a = data.get(SUM_PREFIX + name + part)
            if not isinstance(a, np.ndarray) or a.shape != (H, W, channels):
                raise StpmError(f"{path}: partial result layer {SUM_PREFIX + name + part!r} is missing or has "
                                "the wrong shape")
            parts.append(a)
        x = join64(np.stack(parts, axis=-1))
        if not np.all(np.isfinite(x)):
            raise StpmError(f"{path}: partial result layer {SUM_PREFIX + name!r} holds non-finite values")
        return x

    from .film import ALL_PASSES
    channels = {n: c for n, c, _ in ALL_PASSES}
    for name in names:
        if name not in channels:
            raise StpmError(f"{path}: partial result names an unknown pass {name!r:.40}")
        sums.sums[name] = layer(name, channels[name])
    sums.even = layer("Even", 3) if n_even else None
    sums.odd = layer("Odd", 3) if n_odd else None
    return sums, head


def region_text(region) -> str:
    """A partial's ``region`` in words: 'columns 8..39, rows 4..19' or 'the whole frame'."""
    if region is None:
        return "the whole frame"
    x0, y0, x1, y1 = region
    return f"columns {x0}..{x1 - 1}, rows {y0}..{y1 - 1}"


def merge(paths) -> tuple[PassSums, dict]:
    """The passes of several partial results as one (PassSums over their joint range, the first header).

    Refuses (StpmError, one line) partials of different scenes, seeds, settings, sizes or Render
    Regions (``region``: a region's sums hold its pixels alone), and pass ranges that overlap or
    leave a gap.  The sums are added in pass order.  Partials whose
    ``scene_hash`` differs but whose ``scene_fingerprint`` says the scenes differ only by float
    rounding (Blender's exports are not bit-reproducible: :func:`fingerprint_difference`) are
    merged; the header returned then holds ``scene_rounding`` (the files that differed).
    """
    if not paths:
        raise StpmError("stpm merge needs at least one partial result")
    parts = [(read_partial(p), Path(p)) for p in paths]
    parts.sort(key=lambda x: x[0][1]["pass_first"])
    (total, head0), p0 = parts[0]
    rounding = []
    for key in ("resolution", "region", "seed", "settings_hash", "scene_hash", "passes", "working_space"):
        for (_, head), p in parts[1:]:
            if key == "scene_hash" and head[key] != head0[key]:
                diff = fingerprint_difference(head.get("scene_fingerprint"), head0.get("scene_fingerprint"))
                if diff is None:
                    rounding.append(str(p))
                    continue
                raise StpmError(f"{p} and {p0} are partials of different scenes (another file, frame, camera "
                                f"or edit of the scene; differing: {diff}): they cannot be merged")
            if head[key] != head0[key]:
                if key == "resolution":
                    what = f"resolutions ({'x'.join(map(str, head[key]))} and {'x'.join(map(str, head0[key]))})"
                elif key == "region":
                    what = f"Render Regions ({region_text(head[key])} and {region_text(head0[key])})"
                elif key == "seed":
                    what = f"seeds ({head[key]} and {head0[key]})"
                else:
                    what = {"scene_hash": "scenes (another file, frame, camera or edit of the scene)",
                            "settings_hash": "render settings (besides passes, stops and threads)",
                            "working_space": "working colour spaces", "passes": "render passes"}[key]
                raise StpmError(f"{p} and {p0} are partials of different {what}: they cannot be merged")
    for ((s, head), p), (_, prev) in zip(parts[1:], parts[:-1]):
        if s.first < total.end:
            raise StpmError(f"{p} (passes {s.first}..{s.end - 1}) overlaps passes {total.first}..{total.end - 1} "
                            f"already merged (from {prev})")
        if s.first > total.end:
            raise StpmError(f"passes {total.end}..{s.first - 1} are missing between {prev} and {p}")
        total = total.merged(s)
    if rounding:
        head0 = {**head0, "scene_rounding": rounding}
    return total, head0


