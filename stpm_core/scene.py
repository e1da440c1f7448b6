"""The STPM scene model: plain dataclasses and numpy arrays, no bpy.

Conventions (the whole core follows them):

* World space is Blender's: right-handed, +Z up, metres ("scene units").
* Time is **normalised shutter time** ``u`` in [0, 1] (see :mod:`stpm_core.shutter`).
* Anything that can move carries a :class:`~stpm_core.motion.MotionTransform`
  (one sample = static).  Deforming meshes carry vertex positions per time step.
* Colours are linear RGB float (3,).  Radiometric units match Cycles
  (``shared/design.md``): point/spot of power P watts has intensity
  ``color * P / (4 pi)`` W/sr; an area light of power P is a one-sided
  Lambertian emitter of on-axis intensity ``color * P / pi``; a sun of strength S
  gives irradiance ``color * S`` W/m^2 on a facing surface; surface emission and
  the world colour are radiance in W/(m^2 sr).
* Cameras and lights look down their local -Z axis with +Y up (Blender's).

Validation lives in :func:`validate_scene`; the scene file loader calls it and
so does the renderer, so a half-built scene never renders.
"""
from __future__ import annotations

import hashlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .errors import SceneError
from .motion import MotionTransform
from .shutter import Shutter

__all__ = [
    "Mesh", "Instance", "Camera", "Light", "Material", "World", "Scene",
    "validate_scene", "scene_warnings", "SCENE_FORMAT_VERSION", "MAX_EMISSION", "check_tiles",
]

SCENE_FORMAT_VERSION = 5          # 2 (2026-12-01): material graphs, textures, UV maps, tangents
                                  # 3 (2026-12-07): UDIM tile tables, metadata.working_space (written
                                  # only by files that use them: others stay 2)
                                  # 4 (2026-12-06): per-step normals (K, F, 3, 3) of deforming meshes
                                  # (written only by files that have them)
                                  # 5 (2026-12-07): the camera's thin lens, aperture_radius > 0 (depth
                                  # of field; written only by such files)

#: Largest emission :func:`validate_scene` accepts (docs/scene-format.md, "Limits"):
#: light ``power * max(color)`` (W, or W/m^2 for a sun), material ``emission``
#: and ``world.color * world.strength`` (W/(m^2 sr)).  The passes and the photon
#: records are float32 (largest finite 3.4e38); 1e30 leaves a factor 3.4e8 for
#: what geometry multiplies in (a point light's P / (4 pi d^2) stays finite down
#: to d = 1.5e-5 m, a photon's share of the flux P / n for any n >= 1, density
#: estimates over gather radii >= 1e-4 m).
MAX_EMISSION = 1e30

#: Largest light ``size`` / ``size_y`` (scene units): the loader's limit on coordinates (1e15).
MAX_LIGHT_SIZE = 1e15

#: A transform axis shorter than this (scene units per local unit) counts as
#: zero scale: the direction it should give is undefined.
_ZERO_SCALE = 1e-150


@dataclass
class Mesh:
    """A triangle mesh in object space.

    Attributes
    ----------
    vertices : (V, 3) float32 positions, or (K, V, 3) float32 for a deforming
        mesh whose shape is sampled at ``vertex_times``.
    triangles : (F, 3) int32 vertex indices.
    material_ids : (F,) int32 indices into ``Scene.materials``.
    vertex_times : (K,) float64 increasing normalised times, for deforming
        meshes only (``None`` for a rigid mesh).  Positions are linear between
        steps and clamped outside.
    normals : (F, 3, 3) float32 per-corner shading normals (object space) or
        ``None`` for flat shading.  A deforming mesh may carry them per vertex step,
        (K, F, 3, 3) float32 at ``vertex_times`` (Cycles' ``ATTR_STD_MOTION_VERTEX_NORMAL``):
        like positions, linear between steps and clamped outside, then blended across
        the triangle and normalised (:meth:`normals_at`); (F, 3, 3) on a deforming mesh
        holds the same normals at every step.  Cost: 36 bytes per triangle per step.
    name : str, for messages.
    uv_layers : UV maps by name, each (F, 3, 2) float32 per-corner (u, v) in the
        corner order of ``triangles`` (Blender's loop triangles); {} = no UVs.
    uv_render : name of the render-active UV map (what an Image Texture with an
        unconnected Vector reads); None = the first of ``uv_layers``.
    tangents : per UV map name, (F, 3, 4) float32 per-corner object-space tangent
        (x, y, z) and bitangent sign (Blender's ``Mesh.calc_tangents``: MikkTSpace),
        what a tangent-space Normal Map node reads; {} = none.
    color_layers : colour attributes by name, each (F, 3, 4) float32 per-corner linear RGBA
        (Blender's colour attributes, point or corner domain, at the loop-triangle corners),
        what Color Attribute and Attribute nodes read; {} = none.
    color_render : name of the render-active colour attribute (a Color Attribute node with no
        name reads it), or None.
    orco : (V, 3) float32 undeformed object-space positions (Blender's ``CD_ORCO``: a shape-keyed
        or modifier-deformed mesh's positions before deformation), what Texture Coordinate >
        Generated reads (normalised by their bounding box, Blender's automatic texture space), so
        the texture sticks to the surface as it deforms (Cycles' ``ATTR_STD_GENERATED``); None =
        the vertices (a deforming mesh: at the frame's shutter time, as Cycles without an orco).
    texspace : (2, 3) float64 a manual texture space (Blender's Texture Space panel with Auto
        Texture Space off): row 0 its location, row 1 its size (half extents), object units;
        Generated = (p - (location - size)) / (2 size) per axis (an axis of size 0 reads as size 1,
        as Blender's automatic space does).  None = the automatic space (the bounding box of the
        positions Generated reads).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    material_ids: np.ndarray
    vertex_times: np.ndarray | None = None
    normals: np.ndarray | None = None
    name: str = "mesh"
    uv_layers: dict = field(default_factory=dict)
    uv_render: str | None = None
    tangents: dict = field(default_factory=dict)
    color_layers: dict = field(default_factory=dict)
    color_render: str | None = None
    orco: np.ndarray | None = None
    texspace: np.ndarray | None = None

    @property
    def is_deforming(self) -> bool:
        return self.vertex_times is not None and np.asarray(self.vertices).ndim == 3 and len(self.vertex_times) > 1

    def vertex_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Object-space bounds lo, hi (3,) float64 of the vertices at every time step.

        Cached while ``vertices`` is the same array object (a scene's bounds are
        asked for several times per render; axis-0 reductions of a (V, 3)
        array cost about 1.3 ms per 40k vertices).  Assigning a new array
        recomputes them; editing the array in place is not noticed.
        """
        v = self.vertices
        cached = self.__dict__.get("_vertex_bounds")
        if cached is not None and cached[0] is v:
            return cached[1], cached[2]
        a = np.asarray(v, dtype=np.float64).reshape(-1, 3)
        if a.shape[0] == 0:
            lo = hi = np.full(3, np.nan)
        else:
            t = np.ascontiguousarray(a.T)                # contiguous rows: fast reductions
            lo, hi = t.min(axis=1), t.max(axis=1)
        self.__dict__["_vertex_bounds"] = (v, lo, hi)
        return lo, hi

    def content_digest(self) -> bytes:
        """16-byte digest of the geometry (vertices, triangles, material ids, normals, vertex times).

        Equal digests mean equal meshes: copies of one object (each exported
        as its own Mesh) can share work (the ray caster's object-space scene,
        the effects plan's per-mesh tests).  Cached while the arrays are the
        same objects.
        """
        arrays = (self.vertices, self.triangles, self.material_ids, self.normals, self.vertex_times)
        cached = self.__dict__.get("_digest")
        if cached is not None and all(a is b for a, b in zip(cached[0], arrays)):
            return cached[1]
        h = hashlib.blake2b(digest_size=16)
        for a in arrays:
            if a is None:
                h.update(b"none")
                continue
            a = np.ascontiguousarray(a)
            h.update(str((a.dtype.str, a.shape)).encode())
            h.update(a.data)
        self.__dict__["_digest"] = (arrays, h.digest())
        return h.digest()

    def vertices_at(self, t: float) -> np.ndarray:
        """Object-space vertex positions (V, 3) at normalised time t (scalar)."""
        if not self.is_deforming:
            v = np.asarray(self.vertices)
            return v[0] if v.ndim == 3 else v
        times = np.asarray(self.vertex_times)
        i = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2))
        a = float(np.clip((t - times[i]) / (times[i + 1] - times[i]), 0.0, 1.0))
        return (1 - a) * self.vertices[i] + a * self.vertices[i + 1]

    @property
    def normal_keys(self) -> np.ndarray | None:
        """Corner normals per vertex step (K, F, 3, 3) float32 (K = 1 for a rigid mesh or
        normals shared by every step), or None for flat shading."""
        if self.normals is None:
            return None
        n = np.asarray(self.normals, np.float32)
        return n if n.ndim == 4 else n[None]

    def normals_at(self, t: float) -> np.ndarray | None:
        """Object-space corner normals (F, 3, 3) at normalised time t (scalar), not normalised:
        linear between the steps of ``vertex_times`` like :meth:`vertices_at`; None if flat."""
        N = self.normal_keys
        if N is None or N.shape[0] == 1:
            return None if N is None else N[0]
        times = np.asarray(self.vertex_times)
        i = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2))
        a = float(np.clip((t - times[i]) / (times[i + 1] - times[i]), 0.0, 1.0))
        return (1 - a) * N[i] + a * N[i + 1]


@dataclass
class Instance:
    """A placement of a mesh: ``mesh`` index into ``Scene.meshes`` and its motion.

    shadow_terminator_geometry_offset, shadow_terminator_shading_offset: Blender's object settings
    of those names (Object > Shading in Cycles; defaults 0.1 and 0.0): shadow rays leaving the
    object's smooth-shaded triangles start lifted toward the smooth surface within the cutoff, and
    the shading offset pushes the terminator toward the light (docs/rendering.md, "Shadow
    terminator").  Both finite and >= 0 (Blender's range; its sliders stop at 1).
    """

    mesh: int
    transform: MotionTransform = field(default_factory=MotionTransform.static)
    name: str = "object"
    shadow_terminator_geometry_offset: float = 0.1
    shadow_terminator_shading_offset: float = 0.0


@dataclass
class Camera:
    """A Blender camera (looks down local -Z, +Y up), possibly moving.

    Attributes
    ----------
    type : 'PERSP' or 'ORTHO'.
    transform : camera-to-world motion (scale is ignored, but its three axis
        columns must be non-zero and not parallel: :func:`validate_scene`).
    lens : focal length in mm (perspective).
    sensor_width, sensor_height : mm.
    sensor_fit : 'AUTO', 'HORIZONTAL' or 'VERTICAL' (Blender semantics).
    ortho_scale : width of the view in scene units along the fitted axis (ortho).
    shift_x, shift_y : lens shift in units of the fitted sensor size.
    clip_start, clip_end : scene units along the view axis.
    aperture_radius : thin-lens radius in scene units; 0 = a pinhole (no depth of field).  Blender:
        ``lens / (2 aperture_fstop)`` with the lens in mm converted to m (PERSP), ``1 / (2 fstop)``
        (ORTHO), as Cycles (docs/camera.md, "Depth of field").
    focus_distance : scene units from the lens to the plane in sharp focus, along the view axis
        (a focus object's distance is projected on it by the exporter).  Used when
        ``aperture_radius > 0``.
    aperture_blades : 0 (or 1, 2) = a round aperture; n >= 3 = a regular n-gon (polygonal bokeh).
    aperture_rotation : radians, the polygon's rotation in the lens plane.
    aperture_ratio : anamorphic bokeh: the lens's x extent is divided by it (> 0; 1 = round).
    """

    type: Literal["PERSP", "ORTHO"] = "PERSP"
    transform: MotionTransform = field(default_factory=MotionTransform.static)
    lens: float = 50.0
    sensor_width: float = 36.0
    sensor_height: float = 24.0
    sensor_fit: Literal["AUTO", "HORIZONTAL", "VERTICAL"] = "AUTO"
    ortho_scale: float = 6.0
    shift_x: float = 0.0
    shift_y: float = 0.0
    clip_start: float = 0.1
    clip_end: float = 1000.0
    aperture_radius: float = 0.0
    focus_distance: float = 10.0
    aperture_blades: int = 0
    aperture_rotation: float = 0.0
    aperture_ratio: float = 1.0


@dataclass
class Light:
    """A Blender light, possibly moving (looks down local -Z).

    Attributes
    ----------
    type : 'POINT', 'SPOT', 'AREA' or 'SUN'.
    color : (3,) linear RGB multiplier.
    power : watts for POINT / SPOT / AREA; for SUN, strength in W/m^2.
    transform : light-to-world motion.  SPOT, SUN and AREA lights shine along
        its -Z column (a mirroring scale turns them; a zero Z scale leaves
        them no direction: :func:`scene_warnings`).
    radius : POINT / SPOT sphere radius in scene units (0 = a true point).
    use_soft_falloff : POINT / SPOT: Blender's soft falloff near the sphere.
    spot_size : SPOT full cone angle in radians.
    spot_blend : SPOT edge softness in [0, 1].
    shape : AREA 'SQUARE', 'RECTANGLE', 'DISK' or 'ELLIPSE'.
    size, size_y : AREA extent in scene units (size_y for RECTANGLE / ELLIPSE).
    angle : SUN angular diameter in radians.
    photon_weight : >= 0, this light's share of the photons relative to the others (the add-on's
        ``light.stpm.photon_weight``): photons are split between lights in proportion to
        power x photon_weight, and each light's photons carry its flux divided by their number, so
        the weight moves noise between lights and leaves the image's expectation unchanged
        (docs/photon-mapping.md, "Photon budgets").  0: the light gets no photons (its indirect
        light is then missing).
    """

    type: Literal["POINT", "SPOT", "AREA", "SUN"] = "POINT"
    color: np.ndarray = field(default_factory=lambda: np.ones(3))
    power: float = 1000.0
    transform: MotionTransform = field(default_factory=MotionTransform.static)
    radius: float = 0.0
    use_soft_falloff: bool = True
    spot_size: float = np.pi / 4
    spot_blend: float = 0.15
    shape: Literal["SQUARE", "RECTANGLE", "DISK", "ELLIPSE"] = "SQUARE"
    size: float = 1.0
    size_y: float = 1.0
    angle: float = 0.0
    name: str = "light"
    photon_weight: float = 1.0


@dataclass
class Material:
    """A layered surface in the spirit of the Principled BSDF.

    Lobe weights (they sum to 1 before emission):

    * metal    = ``metallic``                                   (conductor, tinted by base_color)
    * glass    = ``(1 - metallic) * transmission``              (dielectric with Fresnel, ``ior``)
    * dielectric base = ``(1 - metallic) * (1 - transmission)``: Lambertian
      ``base_color`` under a specular dielectric coat whose Fresnel reflectance
      uses ``ior`` scaled by ``specular`` (0 = no coat: a pure Diffuse BSDF).

    ``roughness`` 0 means perfectly specular (mirror / clear glass); above 0 a
    GGX lobe with alpha = roughness^2.  ``emission`` is radiance W/(m^2 sr),
    emitted from both sides of the surface (Cycles does the same).

    Attributes
    ----------
    base_color : (3,) linear albedo in [0, 1].
    metallic, transmission, roughness, specular : float in [0, 1].
    ior : float >= 1 (1 = index-matched: light passes straight through).
    emission : (3,) radiance.
    transmission_tint : (3,) in [0, 1] or None: the colour the glass lobe's refraction is tinted
        by.  None (the default, also :meth:`glass`, as Cycles' Glass BSDF) = ``base_color``; a
        Principled BSDF's is ``sqrt(base_color)`` (Cycles' svm/closure.h), which the exporter sets.
    reflection_tint : (3,) in [0, 1] or None: the colour the glass lobe's reflection is tinted by.
        None (the default, also :meth:`glass`, whose reflection is thus untinted) = white, a
        Principled BSDF's (Cycles' specular tint, white by default); a Glass BSDF's is its colour
        (Cycles' svm/closure.h), which the exporter sets.
    constant_fresnel : bool: the metal lobe reflects ``base_color`` at every angle (Cycles 5.0's
        Glossy BSDF has no Fresnel; the exporter sets it for a Glossy BSDF), not Schlick's
        F0 + (1 - F0)(1 - cos)^5 with F0 = ``base_color`` (a Principled BSDF's metal, the default).
    name : str.
    graph : the material's shader-node graph (:class:`stpm_core.nodes.ShaderGraph`)
        or None.  With a graph, every hit evaluates it (``kernels.svm``); the
        fields above are then the graph's representative constants (what the
        effects plan and the photon budget read).
    """

    base_color: np.ndarray = field(default_factory=lambda: np.full(3, 0.8))
    metallic: float = 0.0
    transmission: float = 0.0
    roughness: float = 0.5
    specular: float = 0.0
    ior: float = 1.5
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    name: str = "material"
    graph: object = None
    transmission_tint: np.ndarray | None = None
    reflection_tint: np.ndarray | None = None
    constant_fresnel: bool = False

    @classmethod
    def diffuse(cls, color=(0.8, 0.8, 0.8), name: str = "diffuse") -> "Material":
        return cls(base_color=np.asarray(color, float), name=name)

    @classmethod
    def mirror(cls, color=(1.0, 1.0, 1.0), roughness: float = 0.0, name: str = "mirror") -> "Material":
        return cls(base_color=np.asarray(color, float), metallic=1.0, roughness=roughness, name=name)

    @classmethod
    def glass(cls, ior: float = 1.5, color=(1.0, 1.0, 1.0), roughness: float = 0.0, name: str = "glass") -> "Material":
        return cls(base_color=np.asarray(color, float), transmission=1.0, ior=ior, roughness=roughness, name=name)

    @classmethod
    def emitter(cls, radiance=(1.0, 1.0, 1.0), name: str = "emission") -> "Material":
        return cls(base_color=np.zeros(3), emission=np.asarray(radiance, float), name=name)

    @property
    def is_specular(self) -> bool:
        """True when some lobe is a delta or glossy lobe (metal, glass, coat)."""
        return self.metallic > 0 or self.transmission > 0 or self.specular > 0

    @property
    def diffuse_weight(self) -> float:
        return (1.0 - self.metallic) * (1.0 - self.transmission)


@dataclass
class World:
    """Background radiance seen by rays that leave the scene, in W/(m^2 sr).

    Constant (``image`` None): ``L = color * strength`` from every direction.

    An environment image (Blender's Environment Texture, equirectangular): the radiance seen
    along a unit direction d (pointing away from the scene) is
    ``L(d) = color * strength * image(u, v)`` with m = mapping^-1 d the direction in the image's
    frame and Cycles' equirectangular coordinates ``u = (pi - atan2(m_y, m_x)) / (2 pi)``,
    ``v = 1 - acos(m_z) / pi`` (v = 1 straight up; docs/lights-and-materials.md, "World").

    image : (H, W, 3) float32 linear RGB, row 0 at the bottom (Blender's pixel order), >= 0.
    mapping : map-to-world rotation over the shutter (the inverse of the Mapping node's
        rotation; a MotionTransform whose matrices are rotations).
    interpolation : 'LINEAR' (bilinear, Repeat) or 'CLOSEST', as the node's.
    camera_image : None (camera rays see ``image`` like every other ray), or (H', W', 3) float32
        (same rules as ``image``, which it needs): what **camera rays** see instead of ``image``
        (Blender's Light Path "Is Camera Ray" = 1 in the world tree; ``image`` holds the world
        with it = 0).  Looked up exactly as ``image``: same direction -> (u, v) rule, ``mapping``,
        ``interpolation`` and ``color * strength`` factor.  A camera ray is a ray from the camera
        that reaches the background directly or only through transparent surfaces (Transparent
        BSDF, alpha cut-outs: they keep Cycles' camera-ray flag); rays after a reflection,
        refraction or diffuse bounce, shadow / next-event rays, the world's light sampling and
        its photons all use ``image``.  The exporter bakes both from Cycles (addon/export/world.py).
    photon_weight : >= 0, the world's share of the photons relative to the lights
        (``world.stpm.photon_weight`` in the add-on; :attr:`Light.photon_weight`).
    """

    color: np.ndarray = field(default_factory=lambda: np.zeros(3))
    strength: float = 1.0
    image: np.ndarray | None = None
    mapping: MotionTransform = field(default_factory=MotionTransform.static)
    interpolation: str = "LINEAR"
    camera_image: np.ndarray | None = None
    photon_weight: float = 1.0

    @property
    def radiance(self) -> np.ndarray:
        """(3,) the constant radiance, or an image world's mean radiance over the sphere of directions."""
        L = np.asarray(self.color, float) * float(self.strength)
        if self.image is None:
            return L
        return L * sphere_mean(self.image)

    @property
    def shines(self) -> bool:
        """Does the world light the scene (some channel of its mean radiance > 0)?"""
        return bool(np.any(self.radiance > 0))


def sphere_mean(image: np.ndarray) -> np.ndarray:
    """(3,) mean over the sphere of directions of an equirectangular image (H, W, 3): row y
    covers polar angles theta in [pi (H - 1 - y) / H, pi (H - y) / H], solid angle proportional to
    cos(theta_0) - cos(theta_1)."""
    H = image.shape[0]
    edges = np.cos(np.pi * (H - np.arange(H + 1)) / H)          # cos(theta) at the row edges, bottom up
    w = edges[1:] - edges[:-1]                                   # (H,) >= 0, sums to 2
    return (w[:, None] * image.astype(np.float64).mean(axis=1)).sum(axis=0) / w.sum()


@dataclass
class Scene:
    """Everything a render needs, for one frame.

    Attributes
    ----------
    meshes, instances, lights, materials : lists of the dataclasses above.
    camera : Camera.
    world : World.
    shutter : Shutter (frames and curve).
    resolution : (width, height) pixels.
    frame : the frame being rendered (informational).
    metadata : free-form strings (exporter version, warnings, source file).
    textures : images the materials' node graphs read (:class:`stpm_core.textures.Texture`),
        referred to by index (an Image Texture node's ``image`` property).
    portals : Blender's light portals (AREA lights with Cycles' ``is_portal``) as AREA
        :class:`Light` entries (shape, size, transform; power and colour unused): openings through
        which the world lights the scene.  They emit nothing and are not seen; next-event
        estimation of the world and world photons are aimed through them
        (docs/lights-and-materials.md, "Light portals").
    """

    meshes: list[Mesh] = field(default_factory=list)
    instances: list[Instance] = field(default_factory=list)
    camera: Camera = field(default_factory=Camera)
    lights: list[Light] = field(default_factory=list)
    materials: list[Material] = field(default_factory=list)
    world: World = field(default_factory=World)
    shutter: Shutter = field(default_factory=Shutter)
    resolution: tuple[int, int] = (320, 240)
    frame: float = 1.0
    metadata: dict = field(default_factory=dict)
    textures: list = field(default_factory=list)
    portals: list[Light] = field(default_factory=list)

    @property
    def has_motion(self) -> bool:
        """Does anything move within the shutter (objects, deformation, camera, lights)?"""
        if self.shutter.is_instant:
            return False
        return (any(not i.transform.is_static for i in self.instances)
                or any(m.is_deforming for m in self.meshes)
                or not self.camera.transform.is_static
                or any(not l.transform.is_static for l in self.lights))

    @contextmanager
    def frozen(self):
        """``with scene.frozen():`` -- the scene does not change inside (one render), so :meth:`bounds`
        and what is derived from it (``raycast.geometry.instance_offsets``) are computed once and kept
        in :meth:`frozen_cache` until the block ends.  A progressive render asks for them every pass.
        Re-entrant: an inner block keeps the outer one's values."""
        if "_frozen" in self.__dict__:
            yield self
            return
        self.__dict__["_frozen"] = {}
        try:
            yield self
        finally:
            self.__dict__.pop("_frozen", None)

    def frozen_cache(self) -> dict | None:
        """The dict :meth:`frozen` keeps values in, or None outside a ``frozen`` block."""
        return self.__dict__.get("_frozen")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space bounds (3,), (3,) of all geometry over the whole shutter."""
        cache = self.frozen_cache()
        if cache is not None:
            if "bounds" not in cache:
                cache["bounds"] = self._bounds()
            lo, hi = cache["bounds"]
            return lo.copy(), hi.copy()
        return self._bounds()

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for inst in self.instances:
            vlo, vhi = self.meshes[inst.mesh].vertex_bounds()
            if not np.all(np.isfinite(vlo)):
                continue                                  # no vertices
            a, b = inst.transform.bounds_of(vlo, vhi)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        if not np.all(np.isfinite(lo)):
            return np.zeros(3), np.zeros(3)
        return lo, hi

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """Centre (3,) and radius (scene units, at least 1e-3) of the sphere around :meth:`bounds`:
        where suns and the world send their photons from."""
        lo, hi = self.bounds()
        return 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)


def _check_finite(name: str, a) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
        raise SceneError(f"{name} contains NaN or inf")
    return a


def _check_vec3(name: str, a, *, nonneg: bool = False) -> None:
    a = _check_finite(name, a)
    if a.shape != (3,):
        raise SceneError(f"{name} must have shape (3,), got {a.shape}")
    if nonneg and np.any(a < 0):
        raise SceneError(f"{name} must be non-negative, got {a.tolist()}")


def _check_range(name: str, v, lo: float, hi: float = np.inf) -> None:
    if not np.isfinite(v) or v < lo or v > hi:
        raise SceneError(f"{name} must be in [{lo}, {hi}], got {v}")


def _check_emission(name: str, value: float, what: str) -> None:
    """Raise SceneError when an emission quantity exceeds :data:`MAX_EMISSION`."""
    if value > MAX_EMISSION:
        raise SceneError(f"{name} is {value:g} {what}, above the limit {MAX_EMISSION:g} "
                         f"(the float32 image and photon records would overflow to inf)")


def _transform_samples(tr: MotionTransform) -> np.ndarray:
    """Matrices (m, 4, 4) of a motion at its keys and halfway between them (where an animated scale may cross 0)."""
    if tr.is_static:
        return tr.matrices
    mid = 0.5 * (tr.times[1:] + tr.times[:-1])
    return np.concatenate([tr.matrices, tr.at(mid)], axis=0)


def _axis_lengths(M: np.ndarray) -> np.ndarray:
    """Lengths (m, 3) of the X, Y, Z columns of matrices M (m, 4, 4), without underflow."""
    A = np.abs(M[:, :3, :3])
    big = np.maximum(A.max(axis=1), 1e-300)                 # (m, 3) per column
    return big * np.sqrt(np.sum((A / big[:, None, :]) ** 2, axis=1))


def _check_camera_lens(c: Camera) -> None:
    """The thin lens (depth of field): radius >= 0, and with a lens a positive focus distance,
    blades an integer in [0, 64], a finite rotation and a positive ratio."""
    def number(name, ok, want):
        v = getattr(c, name, None)
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not ok(float(v)):
            raise SceneError(f"camera.{name} must be {want}, got {v!r:.40}")
    number("aperture_radius", lambda v: 0.0 <= v < 1e6, "a number in [0, 1e6) (scene units; 0 = pinhole)")
    if float(c.aperture_radius) > 0.0:
        number("focus_distance", lambda v: 0.0 < v < 1e9, "a positive finite distance (scene units)")
    b = c.aperture_blades
    if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 0 <= int(b) <= 64:
        raise SceneError(f"camera.aperture_blades must be an integer in [0, 64] (0: round), got {b!r:.40}")
    number("aperture_rotation", lambda v: abs(v) < 1e6, "a finite angle in radians")
    number("aperture_ratio", lambda v: 1e-3 <= v <= 1e3, "a number in [0.001, 1000] (1 = round bokeh)")


def _check_camera_transform(c: Camera) -> None:
    """A camera whose axes cannot form rays (zero scale, collapsed axes) is an error.

    The camera ignores scale (its columns are normalised), so a scale of any
    size and sign renders, but a zero column or two parallel columns leave the
    ray directions undefined: |det| of the column-normalised rotation < 1e-6.
    """
    if not isinstance(c.transform, MotionTransform):
        raise SceneError("camera.transform must be a MotionTransform")
    M = _transform_samples(c.transform)
    ln = _axis_lengths(M)
    Rn = M[:, :3, :3] / np.where(ln > _ZERO_SCALE, ln, np.inf)[:, None, :]
    det = np.abs(np.linalg.det(Rn))
    bad = np.nonzero(~(det >= 1e-6))[0]
    if bad.size:
        k = int(bad[0])
        raise SceneError(f"camera.transform cannot form rays: its X, Y, Z axes have lengths "
                         f"{', '.join(f'{v:.3g}' for v in ln[k])} and |det| {det[k]:.3g} of the normalised axes "
                         f"(zero scale or collapsed axes; any non-zero scale works, the camera ignores it)")


def _check_world_image(world: World) -> None:
    """An environment image: (H, W, 3) finite, >= 0, not too bright; its mapping a rotation over the shutter."""
    if world.interpolation not in ("LINEAR", "CLOSEST"):
        raise SceneError(f"world.interpolation must be LINEAR or CLOSEST, got {world.interpolation!r}")
    if not isinstance(world.mapping, MotionTransform):
        raise SceneError("world.mapping must be a MotionTransform")
    M = _transform_samples(world.mapping)
    R = M[:, :3, :3]
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max()
    if not err < 1e-5 or not np.all(np.linalg.det(R) > 0):
        raise SceneError(f"world.mapping must be a rotation at every key (R R^T = I within 1e-5, got {err:.3g} off)")
    if world.image is not None:
        _check_radiance_image("world.image", world.image, world)
    if world.camera_image is not None:
        if world.image is None:
            raise SceneError("world.camera_image needs world.image (the world every other ray sees)")
        _check_radiance_image("world.camera_image", world.camera_image, world)


def _check_radiance_image(name: str, img, world: World) -> None:
    """An equirectangular radiance image: (H, W, 3) float32, at most 16384 x 8192, finite, >= 0, and
    not brighter than the emission limit once times the world's colour and strength."""
    if not isinstance(img, np.ndarray) or img.ndim != 3 or img.shape[2] != 3 or min(img.shape[:2]) < 1:
        raise SceneError(f"{name} must be an (H, W, 3) array, got {getattr(img, 'shape', type(img).__name__)}")
    if img.dtype != np.float32:
        raise SceneError(f"{name} must be float32, got {img.dtype}")
    if img.shape[0] * img.shape[1] > 16384 * 8192:
        raise SceneError(f"{name} is {img.shape[1]} x {img.shape[0]}: at most 16384 x 8192 pixels")
    if not np.all(np.isfinite(img)) or float(img.min()) < 0.0:
        raise SceneError(f"{name} must be finite and >= 0 (linear radiance)")
    _check_emission(f"{name} * color * strength",
                    float(img.max()) * float(np.max(world.color)) * float(world.strength), "W/(m^2 sr)")


#: a scene whose rays' guard (``raycast.geometry.TMIN_REL`` x its diagonal) exceeds this share of
#: its median object's size is named by :func:`_span_warnings`
SPAN_GUARD_SHARE = 0.1


def _span_warnings(scene: Scene) -> list[str]:
    """One line when the scene is so large next to its objects that rays skip them.

    Rays ignore surfaces nearer to their start than ``TMIN_REL`` (1e-6) x the scene's diagonal:
    one object parked 1e8 units away (a typo, an object "hidden" far off) makes that 100 units,
    and every object near the camera vanishes (artist review 4: a cube at x = 1e8 left a black
    image where Cycles renders the floor; at 1e6 the floor rendered).  Named when that guard
    exceeds ``SPAN_GUARD_SHARE`` of the median object's size, with the object farthest from the
    median object centre."""
    from .raycast.geometry import TMIN_REL, scene_scale
    sizes, centres, names = [], [], []
    for inst in scene.instances:
        vlo, vhi = scene.meshes[inst.mesh].vertex_bounds()
        if not np.all(np.isfinite(vlo)):
            continue
        a, b = inst.transform.bounds_of(vlo, vhi)
        sizes.append(float(np.linalg.norm(b - a))), centres.append(0.5 * (a + b)), names.append(inst.name)
    if len(sizes) < 2:
        return []
    guard = TMIN_REL * scene_scale(scene)
    if not guard > SPAN_GUARD_SHARE * float(np.median(sizes)):
        return []
    C = np.array(centres)
    far = int(np.argmax(np.linalg.norm(C - np.median(C, axis=0), axis=1)))
    dist = float(np.linalg.norm(C[far] - np.median(C, axis=0)))
    return [f"the scene spans {scene_scale(scene):.3g} units ({names[far]!r} lies {dist:.3g} from the other objects): "
            f"rays ignore surfaces nearer than {guard:.3g} units to where they start (1e-6 of the span), so "
            f"objects near the camera can vanish; move {names[far]!r} closer or hide it from renders"]


def scene_warnings(scene: Scene) -> list[str]:
    """Inputs that are valid but render a light black without saying so: one line each.

    * an AREA light with size 0 (or size_y 0 for RECTANGLE / ELLIPSE), or
      whose transform has a zero X or Y scale (zero area);
    * a SPOT, SUN or AREA light whose transform has a zero Z scale (its
      direction, the -Z column, is undefined), or an AREA light whose -Z
      column lies in its plane (no emitting side).

    Transforms are checked at their keys and halfway between them.  A
    mirroring (negative) scale is not a warning: it turns SPOT, SUN and AREA
    lights alike, as in Cycles.  The renderer appends these to its warnings.

    Light portals (``scene.portals``) that cannot do anything are named too: one with no area or
    no emitting side (``world_light.portal_rows`` leaves it out), and one whose emitting side
    (local -Z, into the room) faces away from the camera at mid-shutter.  A portal steers world
    samples only from points on that side (as Cycles'), so a portal placed backwards in a
    window silently stops helping; rotating it 180 degrees about X fixes it.

    A light with some Ray Visibility switch (Diffuse, Glossy, Transmission) off is named with what
    STPM does not honour of it (:func:`light_visibility`).
    """
    out = _portal_warnings(scene) + _light_visibility_warnings(scene) + _span_warnings(scene)
    for li, l in enumerate(scene.lights):
        tr = l.transform
        if l.type not in ("SPOT", "SUN", "AREA") or not isinstance(tr, MotionTransform):
            continue
        who = f"light {l.name!r} ({l.type})"
        M = _transform_samples(tr)
        ln = _axis_lengths(M)
        if l.type == "AREA":
            sy = l.size_y if l.shape in ("RECTANGLE", "ELLIPSE") else l.size
            if l.size <= 0 or sy <= 0:
                out.append(f"{who}: size {l.size:g} x {sy:g} has zero area: the light emits nothing")
                continue
            if np.any(ln[:, :2] <= _ZERO_SCALE):
                out.append(f"{who}: its transform has zero X or Y scale (zero area): the light emits nothing")
                continue
        if np.any(ln[:, 2] <= _ZERO_SCALE):
            out.append(f"{who}: its transform has zero Z scale, so its direction (-Z) is undefined: "
                       f"the light emits nothing")
            continue
        if l.type == "AREA":
            g = np.cross(M[:, :3, 0] / ln[:, 0:1], M[:, :3, 1] / ln[:, 1:2])
            z = M[:, :3, 2] / ln[:, 2:3]
            if np.any(np.abs(np.sum(g * z, axis=1)) < 1e-9):
                out.append(f"{who}: its -Z axis lies in the light's plane (sheared transform): "
                           f"the light emits nothing")
    return out


LIGHT_VISIBILITY_KEYS = (("light_visible_diffuse", 1, "Diffuse"), ("light_visible_glossy", 2, "Glossy"),
                         ("light_visible_transmission", 4, "Transmission"))


def light_visibility(scene: Scene) -> np.ndarray:
    """(L,) uint8 per scene light: the ray kinds that see it (Blender's Object > Visibility > Ray
    Visibility of the light, ``scene.metadata['light_visible_diffuse' / '_glossy' /
    '_transmission']``): bit 1 diffuse, 2 glossy, 4 transmission; 7 (all) where unset.

    Honoured in next-event estimation, lobe by lobe, as Cycles' ``SHADER_EXCLUDE_*`` leaves the
    closures of a hidden kind out of a light sample's BSDF (``kernels.bsdf.bsdf_eval_lobes``: the
    diffuse lobe; the reflection lobes -- coat, metal, glass reflection -- as glossy; glass
    refraction as transmission).  A light with any of them off is not seen by rays leaving a
    surface (next-event estimation carries it whole, without multiple importance sampling), so
    mirror and glass reflections of its shape are missing; photons ignore the switches
    (:func:`scene_warnings` says both)."""
    vis = np.full(len(scene.lights), 7, np.uint8)
    meta = getattr(scene, "metadata", None) or {}
    for key, bit, _name in LIGHT_VISIBILITY_KEYS:
        for li, v in enumerate(list(meta.get(key) or [])[:len(scene.lights)]):
            if not v:
                vis[li] &= np.uint8(7 - bit)
    return vis


def _light_visibility_warnings(scene: Scene) -> list[str]:
    """:func:`scene_warnings`' lines for lights with Ray Visibility switches off."""
    out = []
    for li, v in enumerate(light_visibility(scene)):
        if v == 7:
            continue
        l = scene.lights[li]
        off = ", ".join(name for _key, bit, name in LIGHT_VISIBILITY_KEYS if not v & bit)
        shaped = (l.type == "AREA" or (l.type in ("POINT", "SPOT") and float(getattr(l, "radius", 0.0)) > 0)
                  or (l.type == "SUN" and float(getattr(l, "angle", 0.0)) > 0))
        text = (f"light {l.name!r}: Ray Visibility {off} off is honoured in direct light only: its photons "
                f"(caustic and global maps) ignore it")
        if shaped and v != 0:
            text += "; its shape is not seen in mirror or glass reflections"
        out.append(text)
    return out


def _portal_warnings(scene: Scene) -> list[str]:
    """:func:`scene_warnings`' lines for light portals (one per portal at most)."""
    from .world_light import portal_rows
    portals = list(getattr(scene, "portals", None) or ())
    if not portals:
        return []
    out = []
    cam = np.asarray(scene.camera.transform.at(np.array([0.5]))[0], np.float64)[:3, 3]
    for l in portals:
        who = f"light portal {l.name!r}"
        rows = portal_rows([l]) if isinstance(l.transform, MotionTransform) else np.zeros((0, 12))
        if rows.shape[0] == 0:
            out.append(f"{who}: it has no area or no emitting side: it is ignored")
            continue
        corner, e1, e2, n = rows[0, :3], rows[0, 3:6], rows[0, 6:9], rows[0, 9:12]
        if float((cam - (corner + 0.5 * e1 + 0.5 * e2)) @ n) <= 0.0:
            out.append(f"{who}: its emitting side (-Z) faces away from the camera; a portal guides world light "
                       f"only to points on that side, so it does nothing for the room the camera sees if "
                       f"the room is behind it (rotate it 180 degrees about its X axis)")
    return out


UDIM_FIRST, UDIM_LAST = 1001, 2000         # Blender's UDIM tile numbers


def check_tiles(tiles, where: str, n_textures: int) -> None:
    """An Image Texture's UDIM tile table: a list of [tile number, texture index] pairs, numbers
    distinct in [1001, 2000], indices in [0, n_textures); SceneError naming ``where`` otherwise."""
    ok = isinstance(tiles, (list, tuple)) and len(tiles) <= UDIM_LAST - UDIM_FIRST + 1
    seen = set()
    for t in (tiles if ok else ()):
        ok = (isinstance(t, (list, tuple)) and len(t) == 2
              and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in t)
              and UDIM_FIRST <= t[0] <= UDIM_LAST and 0 <= t[1] < n_textures and int(t[0]) not in seen)
        if not ok:
            break
        seen.add(int(t[0]))
    if not ok:
        raise SceneError(f"{where} must be a list of distinct [tile, texture] pairs, tile in "
                         f"[{UDIM_FIRST}, {UDIM_LAST}] and texture in [0, {n_textures}), got {tiles!r:.80}")


def validate_scene(scene: Scene) -> None:
    """Check every field; raise :class:`SceneError` naming the first bad one.

    Checks shapes, dtypes, NaN/inf, index ranges, enum values, physical
    ranges (negative power, albedo > 1, IOR < 1 ...), emission up to
    :data:`MAX_EMISSION` and a camera transform that can form rays.  Valid
    but suspicious inputs (a light that emits nothing) are reported by
    :func:`scene_warnings` instead.
    """
    for mi, m in enumerate(scene.meshes):
        p = f"meshes[{mi}] ({m.name!r})"
        v = _check_finite(f"{p}.vertices", m.vertices)
        if not (v.ndim in (2, 3) and v.shape[-1] == 3):
            raise SceneError(f"{p}.vertices must have shape (V, 3) or (K, V, 3), got {v.shape}")
        tri = np.asarray(m.triangles)
        if tri.ndim != 2 or tri.shape[1] != 3 or tri.dtype.kind not in "iu":
            raise SceneError(f"{p}.triangles must be an integer array of shape (F, 3), got {tri.dtype} {tri.shape}")
        nv = v.shape[-2]
        if tri.size and (tri.min() < 0 or tri.max() >= nv):
            raise SceneError(f"{p}.triangles index out of range [0, {nv})")
        mid = np.asarray(m.material_ids)
        if mid.shape != (tri.shape[0],) or (mid.size and mid.dtype.kind not in "iu"):
            raise SceneError(f"{p}.material_ids must be an integer array of shape ({tri.shape[0]},), got {mid.shape}")
        if mid.size and (mid.min() < 0 or mid.max() >= len(scene.materials)):
            raise SceneError(f"{p}.material_ids index out of range [0, {len(scene.materials)})")
        if v.ndim == 3:
            if m.vertex_times is None:
                raise SceneError(f"{p}.vertex_times is required when vertices has shape (K, V, 3)")
            vt = _check_finite(f"{p}.vertex_times", m.vertex_times)
            if vt.shape != (v.shape[0],):
                raise SceneError(f"{p}.vertex_times must have shape ({v.shape[0]},), got {vt.shape}")
            if vt.size > 1 and np.any(np.diff(vt) <= 0):
                raise SceneError(f"{p}.vertex_times must be strictly increasing")
        if m.normals is not None:
            n = _check_finite(f"{p}.normals", m.normals)
            # (F, 3, 3), or one set per vertex step (K, F, 3, 3) on a deforming mesh
            steps = v.shape[0] if v.ndim == 3 and v.shape[0] > 1 else 0
            if n.shape != (tri.shape[0], 3, 3) and not (steps and n.shape == (steps, tri.shape[0], 3, 3)):
                per_step = f" or ({steps}, {tri.shape[0]}, 3, 3) (one per vertex step)" if steps else ""
                raise SceneError(f"{p}.normals must have shape ({tri.shape[0]}, 3, 3){per_step}, got {n.shape}")
        if getattr(m, "orco", None) is not None:
            o = _check_finite(f"{p}.orco", m.orco)
            if o.shape != (v.shape[-2], 3):
                raise SceneError(f"{p}.orco must have shape ({v.shape[-2]}, 3), got {o.shape}")
        if getattr(m, "texspace", None) is not None:
            ts = _check_finite(f"{p}.texspace", m.texspace)
            if ts.shape != (2, 3):
                raise SceneError(f"{p}.texspace must have shape (2, 3) (location, size), got {ts.shape}")
        for attr, width in (("uv_layers", 2), ("tangents", 4), ("color_layers", 4)):
            layers = getattr(m, attr, None) or {}
            if not isinstance(layers, dict):
                raise SceneError(f"{p}.{attr} must be a dict of name -> (F, 3, {width}) arrays")
            for name, arr in layers.items():
                a = _check_finite(f"{p}.{attr}[{name!r}]", arr)
                if a.shape != (tri.shape[0], 3, width):
                    raise SceneError(f"{p}.{attr}[{name!r}] must have shape ({tri.shape[0]}, 3, {width}), "
                                     f"got {a.shape}")
    n_tex = len(getattr(scene, "textures", []) or [])
    for ti, tx in enumerate(getattr(scene, "textures", []) or []):
        if not hasattr(tx, "pixels") or getattr(tx, "kind", None) is None:
            raise SceneError(f"textures[{ti}] is not a stpm_core.textures.Texture")
    for mi, mat in enumerate(scene.materials):
        g = getattr(mat, "graph", None)
        if g is None:
            continue
        from .nodes.graph import ShaderGraph
        if not isinstance(g, ShaderGraph):
            raise SceneError(f"materials[{mi}] ({mat.name!r}).graph must be a ShaderGraph")
        for nname, node in g.nodes.items():
            img = node.props.get("image") if node.type == "ShaderNodeTexImage" else None
            if img is not None and not (-1 <= int(img) < n_tex):
                raise SceneError(f"materials[{mi}] ({mat.name!r}).graph node {nname!r}: props['image'] = {img} is "
                                 f"out of range [-1, {n_tex})")
            if node.type == "ShaderNodeTexImage" and "tiles" in node.props:
                check_tiles(node.props["tiles"], f"materials[{mi}] ({mat.name!r}).graph node {nname!r}: "
                                                 f"props['tiles']", n_tex)
    for ii, inst in enumerate(scene.instances):
        if not (0 <= inst.mesh < len(scene.meshes)):
            raise SceneError(f"instances[{ii}] ({inst.name!r}).mesh index {inst.mesh} out of range [0, {len(scene.meshes)})")
        if not isinstance(inst.transform, MotionTransform):
            raise SceneError(f"instances[{ii}].transform must be a MotionTransform")
        for key in ("shadow_terminator_geometry_offset", "shadow_terminator_shading_offset"):
            v = getattr(inst, key, 0.0)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not 0.0 <= float(v) < np.inf:
                raise SceneError(f"instances[{ii}] ({inst.name!r}).{key} must be a finite number >= 0, got {v!r:.40}")
    c = scene.camera
    if c.type not in ("PERSP", "ORTHO"):
        raise SceneError(f"camera.type must be 'PERSP' or 'ORTHO', got {c.type!r}")
    if c.sensor_fit not in ("AUTO", "HORIZONTAL", "VERTICAL"):
        raise SceneError(f"camera.sensor_fit must be AUTO, HORIZONTAL or VERTICAL, got {c.sensor_fit!r}")
    for name in ("lens", "sensor_width", "sensor_height", "ortho_scale", "clip_start"):
        val = getattr(c, name)
        if not np.isfinite(val) or val <= 0:
            raise SceneError(f"camera.{name} must be positive and finite, got {val}")
    for name in ("shift_x", "shift_y"):
        _check_range(f"camera.{name}", getattr(c, name), -1e6, 1e6)
    if not np.isfinite(c.clip_end) or c.clip_end <= c.clip_start:
        raise SceneError(f"camera.clip_end must be finite and > clip_start, got {c.clip_end}")
    _check_camera_lens(c)
    _check_camera_transform(c)
    for li, l in enumerate(scene.lights):
        p = f"lights[{li}] ({l.name!r})"
        if l.type not in ("POINT", "SPOT", "AREA", "SUN"):
            raise SceneError(f"{p}.type must be POINT, SPOT, AREA or SUN, got {l.type!r}")
        _check_vec3(f"{p}.color", l.color, nonneg=True)
        _check_range(f"{p}.power", l.power, 0.0)
        unit = "W/m^2" if l.type == "SUN" else "W"
        _check_emission(f"{p}.power", float(l.power), unit)
        _check_emission(f"{p}.power * max(color)", float(l.power) * float(np.max(l.color)), unit)
        _check_range(f"{p}.radius", l.radius, 0.0)
        _check_range(f"{p}.spot_size", l.spot_size, 0.0, np.pi)
        _check_range(f"{p}.spot_blend", l.spot_blend, 0.0, 1.0)
        _check_range(f"{p}.angle", l.angle, 0.0, np.pi)
        # size / size_y shape only AREA lights, but a negative or absurd one is refused on every type
        _check_range(f"{p}.size", l.size, 0.0, MAX_LIGHT_SIZE)
        _check_range(f"{p}.size_y", l.size_y, 0.0, MAX_LIGHT_SIZE)
        _check_range(f"{p}.photon_weight", getattr(l, "photon_weight", 1.0), 0.0, 1e6)
        if l.type == "AREA":
            if l.shape not in ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"):
                raise SceneError(f"{p}.shape must be SQUARE, RECTANGLE, DISK or ELLIPSE, got {l.shape!r}")
    for mi, m in enumerate(scene.materials):
        p = f"materials[{mi}] ({m.name!r})"
        _check_vec3(f"{p}.base_color", m.base_color, nonneg=True)
        if np.any(np.asarray(m.base_color) > 1.0):
            raise SceneError(f"{p}.base_color must be <= 1 (energy conserving), got {np.asarray(m.base_color).tolist()}")
        _check_vec3(f"{p}.emission", m.emission, nonneg=True)
        _check_emission(f"{p}.emission", float(np.max(m.emission)), "W/(m^2 sr)")
        for tint_name in ("transmission_tint", "reflection_tint"):
            tint = getattr(m, tint_name, None)
            if tint is not None:
                _check_vec3(f"{p}.{tint_name}", tint, nonneg=True)
                if np.any(np.asarray(tint, float) > 1.0):
                    raise SceneError(f"{p}.{tint_name} must be <= 1 (energy conserving), "
                                     f"got {np.asarray(tint, float).tolist()}")
        for name in ("metallic", "transmission", "roughness", "specular"):
            _check_range(f"{p}.{name}", getattr(m, name), 0.0, 1.0)
        _check_range(f"{p}.ior", m.ior, 1.0, 10.0)
    _check_vec3("world.color", scene.world.color, nonneg=True)
    _check_range("world.strength", scene.world.strength, 0.0)
    _check_emission("world.strength", float(scene.world.strength), "W/(m^2 sr)")
    _check_emission("world.color * strength", float(np.max(scene.world.color)) * float(scene.world.strength),
                    "W/(m^2 sr)")
    _check_world_image(scene.world)
    _check_range("world.photon_weight", getattr(scene.world, "photon_weight", 1.0), 0.0, 1e6)
    for pi, l in enumerate(getattr(scene, "portals", None) or ()):
        p = f"portals[{pi}] ({l.name!r})"
        if l.type != "AREA" or l.shape not in ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"):
            raise SceneError(f"{p} must be an AREA light (SQUARE, RECTANGLE, DISK or ELLIPSE), got {l.type} {l.shape}")
        _check_range(f"{p}.size", l.size, 0.0, MAX_LIGHT_SIZE)
        _check_range(f"{p}.size_y", l.size_y, 0.0, MAX_LIGHT_SIZE)
        if not isinstance(l.transform, MotionTransform):
            raise SceneError(f"{p}.transform must be a MotionTransform")
    w, h = scene.resolution
    if int(w) != w or int(h) != h or not (1 <= w <= 65536 and 1 <= h <= 65536):
        raise SceneError(f"resolution must be two integers in [1, 65536], got {scene.resolution}")
