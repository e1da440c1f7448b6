"""Blender depsgraph -> :class:`stpm_core.scene.Scene`, one converter per kind of thing.

:func:`export_scene` is the only entry point.  It needs a way to move the
depsgraph in time: inside a RenderEngine that is ``engine.frame_set(frame,
subframe=...)`` (the render depsgraph follows); the batch path without an
engine passes ``scene.frame_set`` and the view-layer depsgraph.

Steps
1. At the current frame: every instance of ``depsgraph.object_instances``
   (modifiers, geometry-node instances, particles) -> meshes, instances,
   lights; the scene camera; materials; world.
2. If the shutter is open for a while: step through K shutter times, record
   each instance's matrix (and, for meshes that deform, vertex positions).
3. Assemble MotionTransforms (static when nothing moved) and deformation.

Materials that need it carry their node graph (:mod:`.nodes`); the images those graphs read
become ``Scene.textures`` and every mesh carries its UV maps, and the tangents its materials'
tangent-space Normal Maps read (taken at the current frame: a deforming mesh's UVs and
tangents do not change across the shutter).  Shader inputs the interpreter cannot evaluate read
their cached bakes (:mod:`.bake`; :func:`rendered_meshes` lists what a bake plan covers).

The rendered viewport exports with ``motion_blur=False`` (the current frame alone: it cannot move
Blender's frame), ``camera=False`` (it brings the view's camera) and an :class:`.cache.ExportCache`
(meshes, materials and the world of the last export are reused while no update touched them).
"""
from __future__ import annotations

import numpy as np

from .._core import StpmError, scene_model, sub
from . import camera as camera_export
from . import lights as light_export
from . import materials as material_export
from . import mesh as mesh_export
from . import motion
from . import nodes as node_export
from . import world as world_export
from .cache import ExportCache

__all__ = ["export_scene", "ExportCache"]


def _instance_key(inst) -> tuple:
    """A key that names the same instance at every motion step."""
    parent = inst.parent.original.name_full if inst.parent is not None else ""
    pid = tuple(inst.persistent_id) if inst.is_instance else ()
    return (parent, inst.object.original.name_full, pid)


def _warn_once(warnings: list, text: str) -> None:
    if text not in warnings:
        warnings.append(text)


def _hidden_instancer_child(inst) -> bool:
    """A child that its parent instances on vertices/faces renders only as instances.

    The render depsgraph already hides it; the view-layer depsgraph of the
    batch path does not, so apply the render rule here.
    """
    if inst.is_instance:
        return False
    parent = inst.object.parent
    return parent is not None and parent.instance_type in ("VERTS", "FACES")


class _Record:
    """What step 1 learnt about one instance (before motion is known)."""

    __slots__ = ("kind", "name", "obj_name", "matrix", "mesh", "use_motion", "use_deform", "is_instance", "terminator")

    def __init__(self, kind, name, obj_name, matrix, *, mesh=-1, use_motion=True, use_deform=True,
                 is_instance=False, terminator=None):
        self.kind, self.name, self.obj_name, self.matrix = kind, name, obj_name, matrix
        self.mesh, self.use_motion, self.use_deform, self.is_instance = mesh, use_motion, use_deform, is_instance
        self.terminator = terminator or {}     # the object's shadow_terminator_* settings (Instance fields)


def _instance_name(obj, inst) -> str:
    """The name reports and the effects plan use: the object's, 'OBJECT@INSTANCER' for an instance.
    Geometry that geometry nodes instance (Object Info with As Instance off, a mesh primitive) is
    listed by Blender as an object named after the instancer itself ('FruitBed@FruitBed' for every
    orange the review's scatter made); its mesh's name says what it is ('Sphere@FruitBed'). A curve,
    text or metaball's own evaluated mesh (also listed so, no geometry nodes) keeps 'Circle@Circle'."""
    if not inst.is_instance:
        return obj.name
    parent = inst.parent.original
    data, parent_data = getattr(obj, "data", None), getattr(parent, "data", None)
    if (obj.name == parent.name and data is not None and any(m.type == "NODES" for m in parent.modifiers)
            and (parent_data is None or data.name != parent_data.name)):
        return f"{data.name}@{parent.name}"
    return f"{obj.name}@{parent.name}"


def _terminator_settings(obj) -> dict:
    """The object's shadow-terminator settings (Blender's Object properties, which Cycles reads;
    Blender's defaults 0.1 and 0.0 where a build has none), as :class:`stpm_core.scene.Instance` fields."""
    return {key: max(float(getattr(obj, key, default)), 0.0) for key, default in
            (("shadow_terminator_geometry_offset", 0.1), ("shadow_terminator_shading_offset", 0.0))}


def _slot_materials(obj) -> list:
    """The materials of an object's slots (its data's when it has no slots)."""
    return [s.material for s in obj.material_slots] if len(obj.material_slots) else \
        list(getattr(obj.data, "materials", []) or [])


def rendered_meshes(depsgraph):
    """(evaluated object, is_instance, slot materials) of every depsgraph entry whose triangles
    the export renders (the same rule as :func:`export_scene`; used to plan bakes)."""
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type not in mesh_export.GEOMETRY_TYPES or _hidden_instancer_child(inst):
            continue
        if not inst.is_instance and not inst.show_self:
            continue
        if not mesh_export.has_mesh(obj):
            continue
        yield obj, bool(inst.is_instance), _slot_materials(obj)


def default_bakes(depsgraph):
    """The BakeResolver an export uses by default: cached bakes of the open file (:mod:`.bake`)."""
    from . import bake
    return bake.BakeResolver(depsgraph)


def export_scene(depsgraph, frame_set, *, motion_steps: int = 3, bakes="default", motion_blur: bool = True,
                 camera: bool = True, cache: ExportCache | None = None) -> tuple:
    """Export the depsgraph's scene at its current frame.

    Parameters
    ----------
    depsgraph : the evaluated depsgraph (render depsgraph inside an engine).
    frame_set : callable(frame: int, subframe: float) moving the depsgraph in time.
    motion_steps : K, shutter times sampled for moving things (objects' own
        Cycles motion steps raise it).
    bakes : a :class:`.bake.BakeResolver` (inputs the interpreter cannot evaluate read their
        cached bakes; missing ones are named), "default" (one for the open file's cache), or
        None (no baking: such inputs use their defaults, named by the node compiler).
    motion_blur : False: the current frame alone (an instant shutter; ``frame_set`` is never
        called), whatever the scene's motion blur settings.
    camera : False: no camera is exported and none is needed (``Scene.camera`` is a default
        :class:`Camera` the caller replaces: the rendered viewport's view).
    cache : an :class:`.cache.ExportCache` to take unchanged meshes, materials and the world from
        and to keep this export's in (the rendered viewport); None converts everything.

    Returns (Scene, warnings: list[str]).  Raises StpmError when there is no camera (and
    ``camera`` is True).
    """
    scene = depsgraph.scene
    render = scene.render
    warnings: list[str] = []
    frame_now, sub_now = scene.frame_current, float(scene.frame_subframe)
    frame = frame_now + sub_now
    shutter = motion.shutter_from_render(render, frame) if motion_blur else _core_shutter(frame)
    cam_obj = scene.camera if camera else None
    if camera and cam_obj is None:
        raise StpmError(f"scene {scene.name!r} has no active camera")
    if cam_obj is not None and cam_obj.type != "CAMERA":  # Blender lets an Empty or a Light be the scene camera
        raise StpmError(f"the scene camera {cam_obj.name!r} is not a camera object (object type {cam_obj.type}); "
                        f"set a Camera in Scene Properties > Camera")
    cam_name = cam_obj.name_full if cam_obj is not None else None
    if cache is not None:
        cache.begin()

    # 1. Everything at the current frame
    if isinstance(bakes, str):
        try:
            bakes = default_bakes(depsgraph)
        except Exception as e:  # noqa: BLE001 -- never fail an export on the bake cache
            warnings.append(f"baked inputs are not used: the bake cache could not be opened ({type(e).__name__}: {e})")
            bakes = None
    if cache is not None and cache.materials is not None:
        mats = cache.materials            # no material changed since the last export: reuse its conversions
        mats.warnings = warnings
    else:
        mats = material_export.MaterialExporter(warnings, bakes=bakes)
        if cache is not None:
            cache.materials = mats
    meshes: list = []
    mesh_cache: dict = {}
    records: dict = {}
    steps = motion_steps
    cam_matrix = None
    for inst in depsgraph.object_instances:
        obj = inst.object
        key = _instance_key(inst)
        M = np.array(inst.matrix_world, dtype=np.float64)
        use_mb, use_deform, obj_steps = motion.object_motion_settings(obj.original if not inst.is_instance else obj)
        if use_mb:
            steps = max(steps, obj_steps if render.use_motion_blur else 0)
        if obj.type == "CAMERA":
            if obj.original.name_full == cam_name and not inst.is_instance:
                cam_matrix = M
                records[key] = _Record("CAMERA", cam_name, cam_name, M, use_motion=use_mb)
            continue
        if obj.type == "LIGHT":
            if not inst.is_instance:  # light data is read again after the motion steps
                records[key] = _Record("LIGHT", obj.name, obj.original.name_full, M, use_motion=use_mb)
                _warn_light_linking(obj, warnings)
            else:
                _warn_once(warnings, f"light {obj.name!r}: instanced lights are not supported, skipped")
            continue
        if obj.type == "VOLUME" and not _hidden_instancer_child(inst):
            # an OpenVDB Volume object (Add > Volume, smoke / fire caches): Cycles renders it, STPM
            # renders surfaces only; it was skipped without a word (artist review)
            _warn_once(warnings, f"object {obj.name!r}: Volume objects are not rendered (STPM renders "
                                 "surfaces only; volume shaders are ignored too)")
            continue
        if obj.type not in mesh_export.GEOMETRY_TYPES or _hidden_instancer_child(inst):
            continue
        if not inst.is_instance:
            _warn_hair_particles(obj, warnings)
            _warn_ignored_object_flags(obj, warnings)
        if not inst.is_instance and not inst.show_self:  # e.g. a particle emitter set not to render
            continue
        if not mesh_export.has_mesh(obj):
            if obj.type not in mesh_export.MESHED_ELSEWHERE:
                _warn_once(warnings, f"object {obj.name!r}: {obj.type} geometry is not supported, skipped")
            continue
        # Geometry: one Mesh per distinct evaluated data + material mapping
        slot_mats = _slot_materials(obj)
        mat_ids = np.array([mats.index_of(m, obj, inst.is_instance) for m in slot_mats] or [mats.index_of(None)],
                           dtype=np.int32)
        data_key = (obj.data.as_pointer() if inst.is_instance and obj.data is not None else obj.name_full,
                    tuple(mat_ids.tolist()))
        if data_key not in mesh_cache:
            tangent_maps, color_maps = mats.tangent_maps(mat_ids.tolist()), mats.color_maps(mat_ids.tolist())
            texspace = mesh_export.texture_space(obj)
            kept_key = (data_key, tuple(tangent_maps), tuple(color_maps),
                        None if texspace is None else tuple(texspace.ravel().tolist()))
            kept = cache.mesh(kept_key) if cache is not None else None
            if kept is not None:        # unchanged since the last export (ExportCache)
                meshes.append(kept)
                mesh_cache[data_key] = len(meshes) - 1
        if data_key not in mesh_cache:
            me, cleanup = mesh_export.evaluated_mesh(obj)
            if me is None:
                continue
            arr = mesh_export.mesh_arrays(me, tangent_maps=tangent_maps,
                                          warn=lambda text: _warn_once(warnings, text),
                                          color_maps=color_maps)
            cleanup()
            if arr["nonfinite_dropped"]:
                _warn_once(warnings, f"object {obj.name!r}: {arr['nonfinite_dropped']} triangle(s) with NaN, "
                                     f"infinite or huge (beyond {mesh_export.HUGE_COORDINATE:g}) vertex "
                                     f"coordinates left out")
            if arr["triangles"].shape[0] == 0:
                mesh_cache[data_key] = -1
            else:
                slot = np.clip(arr["slots"], 0, len(mat_ids) - 1)
                meshes.append(scene_model.Mesh(vertices=arr["vertices"], triangles=arr["triangles"],
                                               material_ids=mat_ids[slot], normals=arr["normals"],
                                               name=obj.name, uv_layers=arr["uv_layers"],
                                               uv_render=arr["uv_render"], tangents=arr["tangents"],
                                               color_layers=arr["color_layers"],
                                               color_render=arr["color_render"],
                                               orco=mesh_export.orco_positions(obj, arr["vertices"]),
                                               texspace=texspace))
                mesh_cache[data_key] = len(meshes) - 1
                if cache is not None:
                    cache.keep_mesh(kept_key, None if inst.is_instance else obj.original.name_full, meshes[-1])
        if mesh_cache[data_key] < 0:
            continue
        records[key] = _Record("MESH", _instance_name(obj, inst),
                               obj.original.name_full, M, mesh=mesh_cache[data_key], use_motion=use_mb,
                               use_deform=use_deform and not inst.is_instance and obj.type == "MESH",
                               is_instance=inst.is_instance, terminator=_terminator_settings(obj))
    _warn_holdout_collections(getattr(depsgraph, "view_layer", None), warnings)
    if cam_matrix is None and cam_obj is not None:  # a camera hidden from render still defines the view
        cam_eval = cam_obj.evaluated_get(depsgraph)
        cam_matrix = np.array(cam_eval.matrix_world, dtype=np.float64)
        records[("", cam_name, ())] = _Record("CAMERA", cam_name, cam_name, cam_matrix)
    light_data = {r.obj_name: None for r in records.values() if r.kind == "LIGHT"}

    # 2. Motion steps across the shutter
    times = np.array([0.5])
    world_keys: list = []            # the world's Mapping rotation per step, when animated
    samples = {k: [r.matrix] for k, r in records.items()}
    cam_optics: list = []            # the camera's lens, ortho scale and shifts per step
    shapes: dict = {}
    focus_steps: list = []           # the camera's focus distance per step (depth of field)
    step_normals: dict = {}          # key -> [(triangles, normals)] per step of smooth deforming meshes
    if not shutter.is_instant:
        times = motion.step_times(steps)
        samples = {k: [] for k in records}
        shapes = {k: [] for k, r in records.items() if r.kind == "MESH" and r.use_deform}
        world_mapping = world_export.background_nodes(scene.world) if world_export.mapping_is_animated(scene.world) \
            else None
        try:
            for u in times:
                frame_set(*motion.split_frame(float(shutter.to_frame(u))))
                if world_mapping is not None and world_mapping[2] is not None:
                    world_keys.append(world_export.mapping_rotation(world_mapping[2]))
                seen = set()
                for inst in depsgraph.object_instances:
                    key = _instance_key(inst)
                    if key not in samples or key in seen:
                        continue
                    seen.add(key)
                    samples[key].append(np.array(inst.matrix_world, dtype=np.float64))
                    if key in shapes:
                        me = inst.object.data
                        shapes[key].append(mesh_export.vertex_positions(me))
                        if meshes[records[key].mesh].normals is not None:     # smooth: normals per step
                            step_normals.setdefault(key, []).append(mesh_export.step_normals(me))
                if ("", cam_name, ()) in samples and ("", cam_name, ()) not in seen:
                    cam_eval = scene.camera.evaluated_get(depsgraph)
                    samples[("", cam_name, ())].append(np.array(cam_eval.matrix_world, dtype=np.float64))
                if cam_obj is not None:
                    cam_optics.append(camera_export.optics(cam_obj.evaluated_get(depsgraph)))
                if cam_obj is not None and cam_obj.data.dof.use_dof:     # the focus per step: warned if it moves
                    focus_steps.append(camera_export.focus_distance(cam_obj.evaluated_get(depsgraph)))
        finally:
            frame_set(frame_now, sub_now)
        changed = camera_export.optics_changed(cam_optics)
        if changed:
            # Cycles blurs a zoom (the field of view at each motion step); STPM's camera has one
            # lens: the zoom was rendered sharp at the frame's lens without a word (artist review 2)
            warnings.append(f"camera {cam_name!r}: {', '.join(changed)} animated during the shutter: the zoom is "
                            f"not motion-blurred (Cycles blurs it), the frame's value is used")
        for key, r in records.items():
            if len(samples[key]) != len(times):
                warnings.append(f"object {r.name!r} is not present during the whole shutter; rendered without motion")
                samples[key] = [r.matrix]
            elif not r.use_motion:
                samples[key] = [r.matrix]
    # Light data is read at the current frame (after restoring it)
    for inst in depsgraph.object_instances:
        if inst.object.type == "LIGHT" and inst.object.original.name_full in light_data and not inst.is_instance:
            light_data[inst.object.original.name_full] = inst.object

    # 3. Assemble instances, deformation, lights and camera
    instances, lights, portals = [], [], []
    light_seen: list[bool] = []  # Object > Visibility > Camera of each light (Blender's default: off)
    light_rays = {"diffuse": [], "glossy": [], "transmission": []}   # ... > Diffuse / Glossy / Transmission
    cam = None
    for key, r in records.items():
        K = len(samples[key])
        t = times if K == len(times) else np.array([0.5])
        bad = _first_nonfinite_frame(samples[key], t, shutter, frame)
        if bad is not None:
            # A NaN or infinite location / rotation / scale (a keyframe typed as nan, a driver
            # dividing by zero): Cycles leaves such an object out of the image; the whole render
            # used to fail with "transform contains NaN or inf", naming nothing (artist review 2)
            what = {"MESH": "object", "LIGHT": "light", "CAMERA": "camera"}[r.kind]
            text = (f"{what} {r.name!r}: its transform is NaN or infinite at frame {bad:g} "
                    f"(a keyframe, driver or constraint)")
            if r.kind == "CAMERA":
                raise StpmError(text + "; fix the camera's animation")
            warnings.append(text + ": not rendered, as in Cycles")
            continue
        if r.kind == "MESH":
            if r.use_motion and key in shapes and len(shapes[key]) == len(times):
                _attach_deformation(meshes[r.mesh], shapes[key], times, r.name, warnings, step_normals.get(key))
            instances.append(scene_model.Instance(mesh=r.mesh, transform=motion.transform_from_samples(t, samples[key]),
                                                  name=r.name, **r.terminator))
        elif r.kind == "LIGHT":
            obj = light_data.get(r.obj_name)
            if obj is not None and light_export.is_portal(obj):
                portals.append(light_export.export_light(obj, t, samples[key], warnings))
            elif obj is not None:
                lights.append(light_export.export_light(obj, t, samples[key], warnings))
                light_seen.append(bool(getattr(obj, "visible_camera", True)))
                for kind in light_rays:
                    light_rays[kind].append(bool(getattr(obj, f"visible_{kind}", True)))
        elif r.kind == "CAMERA" and cam is None and cam_obj is not None:
            cam = camera_export.export_camera(cam_obj.evaluated_get(depsgraph), t, samples[key], warnings,
                                              focus_steps=focus_steps)
    if cam is None:          # camera=False: the caller brings its own
        cam = scene_model.Camera()
    if cache is not None and cache.world is not None:
        world, world_warnings = cache.world       # the world did not change since the last export
        warnings.extend(w for w in world_warnings if w not in warnings)
    else:
        said = len(warnings)
        world = world_export.export_world(scene.world, warnings, times, world_keys or None, bakes=bakes)
        if cache is not None:
            cache.world = (world, list(warnings[said:]))
    if cache is not None:
        cache.end()

    if abs(render.pixel_aspect_x - render.pixel_aspect_y) > 1e-6:
        warnings.append("non-square pixel aspect is ignored")
    if render.film_transparent and getattr(getattr(scene, "cycles", None), "film_transparent_glass", False):
        # Cycles' Film > Transparent > Transparent Glass makes smooth glass over the transparent
        # background transparent (alpha 0.06 at a glass sphere's centre, measured); STPM renders it
        # opaque, as with the option off: it was ignored without a word (artist review 2)
        warnings.append("Film > Transparent Glass is not supported: glass over the transparent background "
                        "is opaque (alpha 1), as with the option off")
    if not shutter.is_instant and getattr(getattr(scene, "cycles", None), "rolling_shutter_type", "NONE") != "NONE":
        # Cycles' Motion Blur > Rolling Shutter: each row has its own shutter interval; STPM's
        # shutter is global (every pixel sees the whole shutter): ignored without a word before
        warnings.append("Motion Blur > Rolling Shutter is not supported: every row sees the whole shutter "
                        "(a global shutter)")
    out = scene_model.Scene(
        meshes=meshes, instances=instances, camera=cam, lights=lights, portals=portals, materials=mats.materials,
        textures=mats.textures.textures,
        world=world,
        shutter=shutter,
        resolution=camera_export.render_resolution(render), frame=float(frame),
        metadata={"exporter": "stpm-blender", "blender_scene": scene.name, "motion_steps": int(len(times)),
                  "warnings": list(warnings),
                  # Render flags the scene dataclasses have no field for (read by the integrator)
                  "film_transparent": bool(render.film_transparent),
                  "light_visible_camera": light_seen,
                  **{f"light_visible_{kind}": v for kind, v in light_rays.items()},
                  "working_space": _working_space(warnings),
                  **_render_region(render), **_view_settings(scene)})
    return out, warnings


def _view_settings(scene) -> dict:
    """Blender's colour management of the scene (Render Properties > Color Management) as
    metadata: ``stpm render`` writes its PNG through it as Blender writes a PNG (F12 hands Blender
    linear passes and Blender applies it itself).  No machine-specific path goes in (partials of
    one frame rendered on different machines must hash alike): the command line finds Blender's
    OCIO config itself.  Empty if unreadable."""
    try:
        import bpy
        v, d = scene.view_settings, scene.display_settings
        cs = getattr(bpy.data, "colorspace", None)
        return {"view_settings": {
            "display_device": str(d.display_device), "view_transform": str(v.view_transform),
            "look": str(v.look), "exposure": float(v.exposure), "gamma": float(v.gamma),
            "use_curve_mapping": bool(v.use_curve_mapping),
            "working_space": str(getattr(cs, "working_space", "") or "Linear Rec.709")}}
    except Exception:  # noqa: BLE001 -- a preview's colour management never fails an export
        return {}


def _render_region(render) -> dict:
    """Blender's Render Region as metadata for the command line (``stpm render`` cuts or blanks
    the image as Blender writes it; F12 hands Blender the region itself): ``render_region`` =
    [min_x, max_x, min_y, max_y] (fractions of the frame, y from the bottom) and
    ``render_region_crop`` (Crop to Render Region).  Empty without a region."""
    if not getattr(render, "use_border", False):
        return {}
    return {"render_region": [float(render.border_min_x), float(render.border_max_x),
                              float(render.border_min_y), float(render.border_max_y)],
            "render_region_crop": bool(render.use_crop_to_border)}


def _first_nonfinite_frame(matrices: list, times: np.ndarray, shutter, frame: float):
    """The frame of the first of ``matrices`` (sampled at shutter ``times``) holding a NaN or
    infinite entry, or None when all are finite."""
    for u, M in zip(times, matrices):
        if not np.all(np.isfinite(M)):
            return float(shutter.to_frame(float(u))) if len(matrices) > 1 else float(frame)
    return None


def _working_space(warnings: list) -> str:
    """The file's working colour space (Blender 5's ``bpy.data.colorspace.working_space``) as the
    scene's metadata id; one STPM does not know is warned and rendered as Linear Rec.709."""
    import bpy
    name = str(getattr(getattr(bpy.data, "colorspace", None), "working_space", "Linear Rec.709"))
    ws = node_export.working_space()
    if sub("colorspaces").working_id(name) is None:
        _warn_once(warnings, f"working colour space {name!r} is not supported: colours are rendered as "
                             f"Linear Rec.709 (use Linear Rec.709, Linear Rec.2020 or ACEScg)")
    return ws


def _core_shutter(frame: float):
    """An instant shutter at ``frame`` (no motion blur)."""
    return motion.Shutter(open=frame, close=frame)


def _warn_ignored_object_flags(obj, warnings: list) -> None:
    """Object > Visibility switches a Cycles render honours and STPM does not."""
    if not getattr(obj, "visible_camera", True):
        _warn_once(warnings, f"object {obj.name!r}: Ray Visibility > Camera off is ignored (the camera sees it)")
    if not getattr(obj, "visible_shadow", True):
        _warn_once(warnings, f"object {obj.name!r}: Ray Visibility > Shadow off is ignored (it casts shadows)")
    if getattr(obj, "is_holdout", False):
        _warn_once(warnings, f"object {obj.name!r}: Holdout is not supported, rendered as a normal object")
    # Product shots put the object on a Shadow Catcher, and hide helpers from reflections: both were
    # ignored without a word (artist review 2)
    if getattr(obj, "is_shadow_catcher", False):
        _warn_once(warnings, f"object {obj.name!r}: Shadow Catcher is not supported, rendered as a normal object")
    off = [k.title() for k in ("diffuse", "glossy", "transmission") if not getattr(obj, f"visible_{k}", True)]
    if off:
        _warn_once(warnings, f"object {obj.name!r}: Ray Visibility > {' / '.join(off)} off is ignored "
                             f"(indirect rays see it)")
    _warn_light_linking(obj, warnings)   # an emissive mesh can link its light too


def _warn_light_linking(obj, warnings: list) -> None:
    """Blender 4's light and shadow linking (Object > Light Linking / Shadow Linking on the emitter).

    Cycles lights only the receiver collection's objects and lets only the blocker collection's
    cast the emitter's shadows; STPM lights and shadows every object.  It was ignored without a
    word (artist review 4: a key light linked to a car lit the whole ground, 1.8x Cycles there)."""
    link = getattr(obj, "light_linking", None)
    if link is None:
        return
    for attr, what, means in (("receiver_collection", "Light Linking", "it lights every object"),
                              ("blocker_collection", "Shadow Linking", "every object casts its shadows")):
        coll = getattr(link, attr, None)
        if coll is not None:
            _warn_once(warnings, f"object {obj.name!r}: {what} (collection {coll.name!r}) is not supported, "
                                 f"{means}")


def _warn_holdout_collections(view_layer, warnings: list) -> None:
    """View-layer collections set to Holdout (their objects render normally in STPM)."""
    stack = [view_layer.layer_collection] if view_layer is not None else []
    while stack:
        lc = stack.pop()
        if lc.exclude:
            continue
        if lc.holdout:
            _warn_once(warnings, f"collection {lc.name!r}: Holdout is not supported, its objects render normally")
        if lc.indirect_only:
            _warn_once(warnings, f"collection {lc.name!r}: Indirect Only is not supported, its objects render normally")
        stack.extend(lc.children)


def _warn_hair_particles(obj, warnings: list) -> None:
    """Particle-system hair drawn as strands (render as Path) has no triangles: say it is dropped.

    Hair rendered as Object / Collection arrives as instances and is exported.
    """
    for mod in getattr(obj, "modifiers", ()):
        if mod.type != "PARTICLE_SYSTEM" or not mod.show_render:
            continue
        settings = mod.particle_system.settings
        if settings is not None and settings.type == "HAIR" and settings.render_type == "PATH":
            _warn_once(warnings, f"object {obj.name!r}: hair particles ({mod.particle_system.name!r}) "
                                 f"are not rendered (strand hair is not supported)")


def _attach_deformation(mesh, shapes: list, times: np.ndarray, name: str, warnings: list,
                        normals: list | None = None) -> None:
    """Turn a rigid mesh into a deforming one when its vertices move across the steps.

    normals: per step (triangles (F, 3), shading normals (F, 3, 3) or None) of a smooth mesh
    (``mesh_export.step_normals``): the mesh gets normals (K, F, 3, 3), one set per step as Cycles
    stores them (36 bytes per triangle per step); steps whose loop triangles are not the frame's
    (an n-gon triangulated otherwise) keep the frame's normals, with a warning."""
    V = mesh.vertices.shape[0]
    if any(s.shape[0] != V for s in shapes):
        warnings.append(f"object {name!r}: vertex count changes during the shutter; "
                        f"deformation blur skipped, the frame's shape is used")
        return
    stack = np.stack(shapes).astype(np.float32)
    with np.errstate(invalid="ignore"):          # NaN / inf / huge at a step: the frame's position (whose
        bad = ~(np.abs(stack) <= mesh_export.HUGE_COORDINATE).all(axis=2)
    if bad.any():                                # own bad vertices are 0 and unused: mesh_export)
        stack[bad] = np.broadcast_to(np.asarray(mesh.vertices, np.float32), stack.shape)[bad]
    tol = 1e-6 * (1.0 + float(np.abs(stack).max(initial=0.0)))
    if np.abs(stack - stack[:1]).max(initial=0.0) <= tol:
        return  # rigid: nothing deforms
    mesh.vertices = stack
    mesh.vertex_times = np.asarray(times, dtype=np.float64)
    if mesh.normals is None:
        return
    frame = np.asarray(mesh.normals, np.float32)
    if normals is None or len(normals) != len(shapes):
        normals = [(None, None)] * len(shapes)
    keyed, changed = [], False
    for tri, n in normals:
        ok = n is not None and tri is not None and np.array_equal(tri, mesh.triangles)
        changed |= not ok
        keyed.append(np.asarray(n, np.float32) if ok else frame)
    if changed:
        warnings.append(f"object {name!r}: its shading normals could not be read at every motion step; "
                        f"the frame's normals are used at those steps")
    mesh.normals = np.ascontiguousarray(np.stack(keyed))
