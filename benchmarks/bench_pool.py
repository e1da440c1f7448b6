"""The sunlit pool (issue 16): time to Cycles MNEE's caustic quality, against a converged path trace.

Scene: ``blend_scenes/sunlit_pool.blend`` (``make_sunlit_pool.py``): a tiled basin under a single-sheet
glass water surface (IOR 1.33) that a Displace modifier ripples across the shutter (deformation
motion blur, 5 steps), a 5-degree sun at 60 degrees elevation, a camera above the water looking
down through it.  Rendered at RESOLUTION.

* **Converged reference** (not STPM's own): Cycles path tracing, shadow caustics (MNEE) off, at
  CONVERGED_SPP samples, seed 1, bench_room's bounce limits; rendered once and cached in
  ``bench_out/cache/pool/<key>/`` (the key hashes the .blend, its textures, the settings and
  Blender's version).
* **Cycles MNEE**: the file's shadow-caustic flags (water a caster, floor and walls receivers, the
  sun a caustic light) at MNEE_SPP samples, seed 0, wall time of ``bpy.ops.render.render`` after
  a 1-sample warm-up; also the same on a still (motion blur off) for what MNEE does without
  deformation blur.
* **STPM**: method PROGRESSIVE with FINAL_PROGRESSIVE's pass (the add-on's export, kernels warm),
  run for TIME_FACTOR x MNEE's time, its image kept after passes 1, 2, 3, 4, 6, 8, 12, ... with
  the render's elapsed seconds; and the FINAL preset (method PHOTON) once.

Caustic quality: mean LDR-FLIP (Standard view) over the caustic region -- every pixel whose first
hit is the water (the floor and the walls below the surface: all their light comes through the
rippling surface), eroded 2 px -- against the converged reference, and the region's mean
luminance over the reference's.  Reported: ``time_to_mnee_s`` (STPM's first kept image at or
below MNEE's FLIP) and ``time_to_mnee_over_mnee`` (the issue's target: <= 1).

    python -m benchmarks pool      # first run: the reference, about 20-30 min on 2 cores; then ~5 min
"""
from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path

import numpy as np

from benchmarks import bench_room as room

ROOT = Path(__file__).resolve().parent.parent
BLEND = ROOT / "blend_scenes" / "sunlit_pool.blend"
OUT = ROOT / "bench_out" / "pool"
CACHE = ROOT / "bench_out" / "cache" / "pool"
RESOLUTION = (96, 72)
CONVERGED_SPP = 32768
MNEE_SPP = 128
TIME_FACTOR = 4.0
TEXTURE_FILES = ("pool_tiles.png",)
LUMA = room.LUMA
_KEEP = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048)


@contextlib.contextmanager
def _this_scene(**cycles_overrides):
    """bench_room's helpers on this scene (its BLEND, RESOLUTION, TEXTURE_FILES, CYCLES swapped)."""
    names = ("BLEND", "OUT", "CACHE", "RESOLUTION", "CYCLES", "TEXTURE_FILES", "REF_SPP")
    saved = {n: getattr(room, n) for n in names}
    room.BLEND, room.OUT, room.CACHE, room.RESOLUTION = BLEND, OUT, CACHE, RESOLUTION
    room.TEXTURE_FILES, room.REF_SPP = TEXTURE_FILES, CONVERGED_SPP
    room.CYCLES = dict(saved["CYCLES"], **cycles_overrides)
    try:
        yield
    finally:
        for n, v in saved.items():
            setattr(room, n, v)


def _mnee(scene, on: bool) -> None:
    """Cycles' shadow-caustic flags of every object and light on or off."""
    for obj in scene.objects:
        if obj.type == "MESH":
            obj.cycles.is_caustics_caster = on and obj.name == "Water"
            obj.cycles.is_caustics_receiver = on and obj.name != "Water"
        elif obj.type == "LIGHT":
            obj.data.cycles.is_caustics_light = on


def reference() -> tuple[np.ndarray, np.ndarray, float, bool]:
    """(converged Cycles RGB (H, W, 3), object-index image (H, W), seconds, was it cached)."""
    with _this_scene(seed=1):
        d = CACHE / room._cache_key()
        if (d / "cycles.npy").exists() and (d / "index.npy").exists() and (d / "meta.json").exists():
            meta = json.loads((d / "meta.json").read_text())
            return np.load(d / "cycles.npy"), np.load(d / "index.npy"), float(meta["seconds"]), True
        d.mkdir(parents=True, exist_ok=True)
        index, _ = room._cycles(room._open(), 1, d / "index.exr", index_pass=True)
        print(f"bench_pool: rendering the converged reference (Cycles path tracing, {CONVERGED_SPP} spp, "
              f"{RESOLUTION[0]} x {RESOLUTION[1]}) into {d}", flush=True)
        scene = room._open()
        _mnee(scene, False)
        rgb, seconds = room._cycles(scene, CONVERGED_SPP, d / "cycles.exr")
        np.save(d / "cycles.npy", rgb.astype(np.float32))
        np.save(d / "index.npy", index)
        import bpy
        (d / "meta.json").write_text(json.dumps({"seconds": seconds, "spp": CONVERGED_SPP, "cycles": room.CYCLES,
                                                 "blender": bpy.app.version_string,
                                                 "when_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}))
        for name in ("index.exr", "cycles.exr"):
            (d / name).unlink(missing_ok=True)
    return rgb.astype(np.float32), index, seconds, False


def cycles_mnee(motion_blur: bool = True) -> tuple[np.ndarray, float]:
    """(Cycles with shadow caustics at MNEE_SPP, wall seconds) after a 1-sample warm-up."""
    OUT.mkdir(parents=True, exist_ok=True)
    with _this_scene(seed=0):
        for spp in (1, MNEE_SPP):
            scene = room._open()
            scene.render.use_motion_blur = motion_blur
            _mnee(scene, True)
            rgb, seconds = room._cycles(scene, spp, OUT / "mnee.exr")
    (OUT / "mnee.exr").unlink(missing_ok=True)
    return rgb, seconds


def stpm_progressive(time_limit: float) -> tuple[list[tuple[int, float, np.ndarray]], dict]:
    """([(pass, elapsed s, RGB)] kept after the passes in _KEEP and the last, stats) of STPM PROGRESSIVE
    with FINAL_PROGRESSIVE's pass for ``time_limit`` seconds (export included, kernels warm)."""
    from addon import batch
    from addon.presets import PRESETS
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    with _this_scene():
        scene = room._open()
        t0 = time.perf_counter()
        core, settings = batch.export_current(scene)
        export_s = time.perf_counter() - t0
    settings.update({k: v for k, v in PRESETS["FINAL_PROGRESSIVE"].items() if k != "motion_steps"})
    settings.update(passes=0, noise_threshold=0.0, time_limit=float(time_limit))
    render(core, RenderSettings.from_dict(dict(settings, passes=2, time_limit=0.0, photons_caustic=5000,
                                               photons_global=2000)))          # warm-up: kernels compiled
    kept = []

    def on_pass(passes, info):
        i = int(info["pass"])
        if i in _KEEP or i % 1024 == 0:
            kept.append((i, export_s + float(info["elapsed_s"]), np.array(passes["Combined"][..., :3], np.float64)))

    res = render(core, RenderSettings.from_dict(settings), on_pass=on_pass)
    final = np.asarray(res.passes["Combined"][..., :3], np.float64)
    n = int(res.stats.get("passes", kept[-1][0] if kept else 0))
    if not kept or kept[-1][0] != n:
        kept.append((n, export_s + float(res.stats.get("render_s", res.stats.get("wall_s", 0.0))), final))
    return kept, {"export_s": export_s, "passes": n}


def stpm_final() -> tuple[np.ndarray, float]:
    """(STPM with the FINAL preset, seconds of export + render) (kernels warm)."""
    with _this_scene():
        rgb, _passes, timings = room.stpm_final(warm=False)
    return rgb, timings["export_s"] + timings["render_s"]


def caustic_region(index: np.ndarray, names: list[str]) -> np.ndarray:
    """Pixels whose first hit is the water, eroded 2 px (the floor and walls seen through it)."""
    return room._erode(index == names.index("Water") + 1, 2)


def _bin2(x: np.ndarray) -> np.ndarray:
    """2 x 2 box average of (H, W, ...) (H, W even)."""
    H, W = x.shape[0] // 2 * 2, x.shape[1] // 2 * 2
    return x[:H, :W].reshape(H // 2, 2, W // 2, 2, *x.shape[2:]).mean(axis=(1, 3))


def score(rgb: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict:
    """{flip: mean LDR-FLIP over mask, flip2: the same on 2 x 2-binned images (the reference's own
    per-pixel noise halved: a path-traced caustic of a 5-degree sun is still grainy at
    CONVERGED_SPP), ratio: mean luminance / the reference's, corr: 8 x 8 block correlation of the
    masked luminance}."""
    _, fmap = room.flip_ldr(rgb, ref)
    _, fmap2 = room.flip_ldr(_bin2(rgb), _bin2(ref))
    m2 = _bin2(mask.astype(float)) == 1.0
    y, yr = rgb @ LUMA, ref @ LUMA
    return {"flip": float(fmap[mask].mean()), "flip2": float(fmap2[m2].mean()),
            "ratio": float(y[mask].mean() / max(yr[mask].mean(), 1e-12)),
            "corr": room.block_corr(np.where(mask[..., None], rgb, 0.0), np.where(mask[..., None], ref, 0.0))}


def run() -> dict:
    missing = room.missing_requirements()
    if missing is not None:
        return missing
    OUT.mkdir(parents=True, exist_ok=True)
    ref, index, ref_s, cached = reference()
    with _this_scene():
        room._open()
        names = room.object_names()
    mask = caustic_region(index, names)
    out = {"resolution": f"{RESOLUTION[0]}x{RESOLUTION[1]}", "caustic_px": int(mask.sum()),
           "reference_spp": CONVERGED_SPP, "reference_s": ref_s, "reference_cached": cached}
    mnee, mnee_s = cycles_mnee(True)
    m = score(mnee, ref, mask)
    out.update({"mnee_s": mnee_s, "mnee_flip": m["flip"], "mnee_flip2": m["flip2"], "mnee_ratio": m["ratio"],
                "mnee_corr": m["corr"]})
    still, still_s = cycles_mnee(False)
    ms = score(still, ref, mask)
    out.update({"mnee_still_s": still_s, "mnee_still_ratio": ms["ratio"]})
    kept, info = stpm_progressive(TIME_FACTOR * mnee_s)
    curve = []
    reach = reach2 = None
    for i, t, rgb in kept:
        s = score(rgb, ref, mask)
        curve.append({"pass": i, "s": round(t, 2), **{k: round(v, 4) for k, v in s.items()}})
        if reach is None and s["flip"] <= m["flip"]:
            reach = t
        if reach2 is None and s["flip2"] <= m["flip2"]:
            reach2 = t
    last = curve[-1]
    out.update({"stpm_passes": info["passes"], "stpm_s": last["s"], "stpm_flip": last["flip"],
                "stpm_flip2": last["flip2"], "stpm_ratio": last["ratio"], "stpm_corr": last["corr"],
                "time_to_mnee_s": reach if reach is not None else float("nan"),
                "time_to_mnee_over_mnee": (reach / mnee_s) if reach is not None else float("nan"),
                "time_to_mnee2_s": reach2 if reach2 is not None else float("nan"),
                "time_to_mnee2_over_mnee": (reach2 / mnee_s) if reach2 is not None else float("nan")})
    final, final_s = stpm_final()
    f = score(final, ref, mask)
    out.update({"final_s": final_s, "final_flip": f["flip"], "final_flip2": f["flip2"], "final_ratio": f["ratio"],
                "final_corr": f["corr"]})
    (OUT / "curve.json").write_text(json.dumps(curve, indent=1))
    # the picture: reference | Cycles MNEE | STPM at MNEE's time (or its last) | STPM FINAL
    at = next((rgb for i, t, rgb in kept if t >= mnee_s), kept[-1][2])
    row = np.concatenate([ref, mnee, at, final], axis=1)
    room._write_display(OUT / "pool_ref_mnee_stpm_final.png", room.standard_view(row))
    out["picture"] = str((OUT / "pool_ref_mnee_stpm_final.png").relative_to(ROOT))
    out["sources"] = room.sources_digest()
    return out


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
