"""Build the caustic and global photon maps and answer irradiance look-ups.

    maps = build_photon_maps(scene, settings, caster, lights)
    E = maps.estimate('caustic', p, ns, t)      # (n, 3) W/m^2; times albedo / pi = radiance

The estimator (settings.estimator), k (settings.k_nearest), kernel,
temporal_alpha and time_scale come from the settings; ``estimate`` also takes
them as keyword overrides so one map can be read by all three estimators.
"""
from __future__ import annotations

import time as _time

import numpy as np

from ..bsdf import MaterialTable
from .estimators import PhotonMap, auto_temporal_alpha
from .record import BYTES_PER_PHOTON, photon_origin
from .timescale import auto_time_scale
from .trace import trace_caustic_map, trace_global_map

__all__ = ["PhotonMaps", "build_photon_maps", "KINDS"]

KINDS = ("caustic", "global")
#: the maps whose k-nearest searches are bounded (``PhotonMap(bounded=True)``; ``estimators.SEARCH_CAP``
#: switches it off): the caustic map, where most look-ups lie far from every caustic and each one
#: summed kq photons for a density of almost nothing (docs/photon-mapping.md, "Bounded searches")
BOUNDED_MAPS = ("caustic",)
#: the maps whose look-ups correct the disc's boundary bias at a surface's edge (``PhotonMap(edge=True)``;
#: ``estimators.EDGE_CORRECTION`` switches it off): the global map, whose photons end where a surface ends;
#: the caustic map's also end where a caustic does (docs/photon-mapping.md, "Edges and corners")
EDGE_MAPS = ("global",)


class PhotonMaps:
    """The caustic and global maps of one render (or of one accumulation still).

    Attributes
    ----------
    maps : {'caustic': PhotonMap, 'global': PhotonMap}.
    estimator, k, kernel, temporal_alpha : defaults for :meth:`estimate`.
    time_scale : KD4D's s in scene units per shutter (resolved: never 0).
    """

    def __init__(self, maps: dict, *, estimator: str, k: int, kernel: str, temporal_alpha: float,
                 time_scale: float, info: dict | None = None):
        self.maps = maps
        self.estimator = estimator
        self.k = int(k)
        self.kernel = kernel
        self.temporal_alpha = float(temporal_alpha)
        self.time_scale = float(time_scale)
        self._info = dict(info or {})

    shares_lookups = True    # estimate(..., support=True) gives what photons.sharing needs
    reads_standard = True    # estimate(..., estimator='STANDARD') reads any map (integrator.static_view_setup)
    gather_cache = None      # photons.gather.IrradianceCache with final gathering (else None)

    def has(self, kind: str) -> bool:
        """Does the ``kind`` map hold any photon?"""
        return self.maps[kind].n > 0

    def prepare_standard(self) -> None:
        """Build now the trees STANDARD reads (static views of a TEMPORAL or KD4D render,
        ``integrator.static_view_setup``), so they count as map building, not as look-ups."""
        for m in self.maps.values():
            m.build("STANDARD", k=self.k)

    @property
    def glossy_lookups(self) -> bool:
        """Can :meth:`estimate` weigh caustic photons by a rough lobe (``glossy``)?  The compiled
        search only (``PhotonMap.estimate``)."""
        m = self.maps.get("caustic")
        return m is not None and m.n > 0 and m.backend == "numba"

    def estimate(self, kind: str, p: np.ndarray, ns: np.ndarray, t: np.ndarray, *, estimator: str | None = None,
                 k: int | None = None, kernel: str | None = None, temporal_alpha: float | None = None,
                 support: bool = False, glossy=None, ng: np.ndarray | None = None, back: float | None = None):
        """Irradiance E (n, 3) W/m^2 at p (n, 3) on the ns (n, 3) side at shutter times t (n,).

        ng (n, 3): the queries' unit geometric normals (None: no slab), whose tangent slab bounds
        the photons counted (``PhotonMap.estimate``; zero rows: no slab for those queries); back:
        the slab's back fraction (None: ``estimators.PLANE_FRACTION``; >= 1: the photon-normal test alone).

        Zeros where the map is empty.  Keyword overrides default to the settings.  support: return
        ``(E, r, tau, lo, hi)``, the region each estimate read (``PhotonMap.estimate``).  glossy:
        return (E, L_g), L_g the radiance the query's rough lobes reflect of the delta-only photons
        (``PhotonMap.estimate``; :attr:`glossy_lookups` says whether the map can).
        """
        if kind not in self.maps:
            raise ValueError(f"unknown photon map {kind!r} (expected one of {KINDS})")
        return self.maps[kind].estimate(
            p, ns, t,
            estimator=estimator or self.estimator,
            k=self.k if k is None else int(k),
            kernel=(kernel or self.kernel).upper(),
            temporal_alpha=self.temporal_alpha if temporal_alpha is None else float(temporal_alpha),
            support=support, glossy=glossy, ng=ng, back=back)

    @property
    def stats(self) -> dict:
        """Photons stored per map, bytes per photon, tree build and look-up seconds, trace seconds."""
        st = dict(self._info)
        if self.gather_cache is not None:
            st.update(self.gather_cache.stats)          # final gathering: cache build and misses
        build = lookup = 0.0
        count = 0
        for kind, m in self.maps.items():
            st[f"photons_{kind}"] = m.n
            st[f"{kind}_tree_build_s"] = m.stats["tree_build_s"]
            st[f"{kind}_lookup_s"] = m.stats["lookup_s"]
            st[f"{kind}_lookup_count"] = m.stats["lookup_count"]
            st[f"{kind}_capped_count"] = m.stats["capped_count"]
            st[f"{kind}_temporal_candidates"] = m.stats["temporal_candidates"]
            st[f"{kind}_temporal_slices"] = m.stats.get("temporal_slices", 1)
            build += m.stats["tree_build_s"]
            lookup += m.stats["lookup_s"]
            count += m.stats["lookup_count"]
        n_total = sum(m.n for m in self.maps.values())
        st.update({
            "bytes_per_photon": BYTES_PER_PHOTON,
            "photon_record_bytes": BYTES_PER_PHOTON * n_total,
            "photon_map_build_s": build,
            "tree_build_s": build,
            "lookup_s": lookup,
            "lookup_count": count,
            "lookups_per_s": count / lookup if lookup > 0 else 0.0,
            "lookup_backend": next((m.backend for m in self.maps.values() if m.n), "scipy"),
            "estimator": self.estimator,
            "k_nearest": self.k,
            "kernel": self.kernel,
            "time_scale": self.time_scale,
            "temporal_alpha": self.temporal_alpha if self.temporal_alpha >= 1.0
            else auto_temporal_alpha(max((m.n for m in self.maps.values()), default=0), self.k),
        })
        return st


def build_photon_maps(scene, settings, caster, lights, *, time_override=None, progress=None,
                      cancel=None, build_trees: bool = True) -> PhotonMaps:
    """Trace ``settings.photons_caustic`` + ``settings.photons_global`` photons and build the maps.

    Parameters
    ----------
    scene : Scene; settings : RenderSettings; caster : from make_caster(scene);
    lights : LightSet(scene).
    time_override : float or None -- every photon path at this one shutter time
        (an accumulation-buffer still); estimates then reduce to STANDARD.  A tuple (lo, hi) of
        shutter mass: photon times stratified over that part of the shutter only (a progressive
        pass's time stratum).
    progress : progress(fraction, message) or None; cancel : () -> bool or None
        (raises RenderCancelled between batches).
    build_trees : build the trees ``settings.estimator``'s k-nearest look-ups need now (False: a
        progressive pass, whose fixed regions build their own structure on first use).
    """
    table = MaterialTable(scene.materials)
    s = float(settings.time_scale) if settings.time_scale > 0 else auto_time_scale(scene)
    workers = -1 if int(getattr(settings, "threads", 0)) == 0 else int(settings.threads)
    info: dict = {}

    def span(a, b):
        return None if progress is None else (lambda f, msg: progress(a + (b - a) * f, msg))

    # -- Trace both maps ---------------------------------------------------------------
    t0 = _time.perf_counter()
    n_c, n_g = int(settings.photons_caustic), int(settings.photons_global)
    split = n_c / max(n_c + n_g, 1)
    rec_c, ic = trace_caustic_map(scene, settings, caster, lights, table, time_override=time_override,
                                  progress=span(0.0, 0.9 * split), cancel=cancel)
    # With final gathering, the global photons that made no DIFFUSE-lobe bounce (only rough coats:
    # L (S|G|C)* C (S|G|C)* D) go to the caustic map, which camera vertices read; gather rays do not
    # bring those paths to the camera vertex (docs/photon-mapping.md, "The path partition with final
    # gathering")
    coat: list = []
    rec_g, ig = trace_global_map(scene, settings, caster, lights, table, time_override=time_override,
                                 progress=span(0.9 * split, 0.9), cancel=cancel, coat_paths=coat)
    if coat and coat[0].shape[0]:
        rec_c = np.concatenate([rec_c, coat[0]])
    info.update(ic)
    info.update(ig)
    info["photon_trace_s"] = _time.perf_counter() - t0
    info["photons_emitted"] = ic["photons_emitted_caustic"] + ig["photons_emitted_global"]
    info["photons_per_s"] = info["photons_emitted"] / info["photon_trace_s"] if info["photon_trace_s"] > 0 else 0.0

    # -- Build the search structure the chosen estimator needs ----------------------------
    origin = photon_origin(scene)  # the records' positions are relative to it (record.py)
    maps = {kind: PhotonMap(rec, scene.shutter, time_scale=s, workers=workers, origin=origin,
                            bounded=kind in BOUNDED_MAPS, edge=kind in EDGE_MAPS)
            for kind, rec in (("caustic", rec_c), ("global", rec_g))}
    for m in maps.values() if build_trees else ():
        m.build(settings.estimator, k=settings.k_nearest, temporal_alpha=settings.temporal_alpha)
    out = PhotonMaps(maps, estimator=settings.estimator, k=settings.k_nearest, kernel=settings.kernel,
                     temporal_alpha=settings.temporal_alpha, time_scale=s, info=info)
    # -- Final gathering: irradiance precomputed at every 4th global photon (photons.gather; its
    #    direct part is added by the integrator, which has the lights) --------------------------
    if int(getattr(settings, "final_gather_samples", 0)) > 0 and int(settings.diffuse_bounces) >= 2 \
            and maps["global"].n > 0:
        from .gather import IrradianceCache
        lo, hi = scene.bounds()
        out.gather_cache = IrradianceCache.build(out, caster, scene_extent=float(np.linalg.norm(hi - lo)),
                                                 caustics=True)
    if progress is not None:
        progress(1.0, "photon maps built")
    return out
