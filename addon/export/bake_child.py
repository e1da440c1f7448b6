"""The bake child process of :mod:`addon.export.bake` (standalone: imports nothing of the add-on).

Run as ``blender -b --factory-startup COPY.blend --python bake_child.py -- SPEC.json`` (real
Blender) or ``python bake_child.py SPEC.json`` (the pip ``bpy`` module: the copy is opened here).
SPEC.json (written by :func:`addon.export.bake.run_jobs`) holds ``blend`` (the copy), ``scene``,
``view_layer``, ``frame``, ``samples``, ``result`` (where to write the results) and ``jobs``
(:class:`addon.export.bake.Job` as dicts).

The copy is never saved.  Per job, in the job's material: a new Emission shader (Strength 1)
takes the socket that feeds the input and drives a new, active Material Output; a new active
Image Texture node holds a float image (the file's working space, Linear Rec.709 by default, for
colours, Non-Color for scalars and data); every other material of the object gets a scratch image as its active node (Cycles bakes
each face into its own material's active image).  Cycles bakes EMIT on the job's UV map
(``samples`` samples, margin ``max(4, res // 64)`` texels, Extend) with only that object
selected, and the image is written as a linear 32-bit float EXR with ``Image.save_render`` and
colour management overridden to the working space (``Image.save`` applies the display transform)
as ``<key>.exr`` (renamed into place), with a ``<key>.json`` note beside it.  Render visibility
is applied first (viewport flags := render flags, as ``addon.batch.render_visibility`` does for
the export), so the bake sees the objects and modifiers F12 renders.  Results: ``[{"key", "ok", "seconds", "error"}]``.

A job with ``"type": "world"`` (:class:`addon.export.world.WorldJob`) renders a world alone into an
equirectangular EXR instead (:mod:`world_bake_child`, beside this script).
"""
from __future__ import annotations

import json
import os
import sys
import time
import traceback


def _spec_path() -> str:
    argv = sys.argv
    rest = argv[argv.index("--") + 1:] if "--" in argv else argv[1:]
    if not rest:
        raise SystemExit("bake_child.py: no spec file given")
    return rest[0]


def _render_visibility(bpy, view_layer) -> None:
    for coll in bpy.data.collections:
        if coll.library is None:
            coll.hide_viewport = coll.hide_render
    stack = [view_layer.layer_collection]
    while stack:
        lc = stack.pop()
        if not lc.exclude:
            lc.hide_viewport = False
        stack.extend(lc.children)
    for obj in bpy.data.objects:
        if obj.library is not None:
            continue
        obj.hide_viewport = obj.hide_render
        for mod in obj.modifiers:
            mod.show_viewport = mod.show_render
            if mod.type in ("SUBSURF", "MULTIRES"):
                mod.levels = mod.render_levels
    for obj in view_layer.objects:
        if obj.hide_get(view_layer=view_layer):
            obj.hide_set(False, view_layer=view_layer)


def _working(bpy) -> str:
    """The file's working colour space (Blender 5; Blender 4: Linear Rec.709): bakes are written in
    it, so the export reads them as scene-linear values with no conversion."""
    return str(getattr(getattr(bpy.data, "colorspace", None), "working_space", "Linear Rec.709"))


def _linear_exr(settings) -> None:
    """Image settings for ``Image.save_render``: RGB 32-bit float OpenEXR, linear in the working
    space (no view transform, no conversion)."""
    import bpy
    if hasattr(settings, "media_type"):
        settings.media_type = "IMAGE"
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGB"
    settings.color_depth = "32"
    if hasattr(settings, "exr_codec"):
        settings.exr_codec = "ZIP"
    if hasattr(settings, "color_management"):
        settings.color_management = "OVERRIDE"
        if hasattr(settings, "linear_colorspace_settings"):
            settings.linear_colorspace_settings.name = _working(bpy)


def _active_image_node(bpy, mat, image):
    """Make an Image Texture node holding ``image`` the active (bake target) node of ``mat``."""
    tree = mat.node_tree
    node = tree.nodes.get("stpm bake target")
    if node is None:
        node = tree.nodes.new("ShaderNodeTexImage")
        node.name = "stpm bake target"
    node.image = image
    for n in tree.nodes:
        n.select = False
    node.select = True
    tree.nodes.active = node


def _bake(bpy, scene, view_layer, job: dict, samples: int, scratch) -> None:
    obj = bpy.data.objects.get(job["object"])
    if obj is None:
        raise RuntimeError(f"object {job['object']!r} not found in the copy")
    mat = bpy.data.materials.get(job["material"])
    if mat is None or mat.node_tree is None:
        raise RuntimeError(f"material {job['material']!r} (with nodes) not found in the copy")
    if obj.name not in view_layer.objects:        # an instance's original object, not in the scene itself
        scene.collection.objects.link(obj)
    tree = mat.node_tree
    consumer = tree.nodes.get(job["node"])
    if consumer is None:
        raise RuntimeError(f"node {job['node']!r} not found in material {mat.name!r}")
    sock = next((s for s in consumer.inputs if s.identifier == job["socket"]), None)
    links = [l for l in (sock.links if sock is not None else ()) if l.is_valid and not getattr(l, "is_muted", False)]
    if not links:
        raise RuntimeError(f"input {job['socket']!r} of node {job['node']!r} is not linked")
    src = links[0].from_socket
    # Emission of the source on a new active output
    em = tree.nodes.get("stpm bake emission") or tree.nodes.new("ShaderNodeEmission")
    em.name = "stpm bake emission"
    em.inputs["Strength"].default_value = 1.0
    out = tree.nodes.get("stpm bake output") or tree.nodes.new("ShaderNodeOutputMaterial")
    out.name = "stpm bake output"
    out.target = "ALL"
    tree.links.new(src, em.inputs["Color"])
    tree.links.new(em.outputs[0], out.inputs["Surface"])
    for n in tree.nodes:
        if n.bl_idname == "ShaderNodeOutputMaterial" and n != out:
            n.is_active_output = False
    out.is_active_output = True
    # Target image and scratch images for the object's other materials
    res = int(job["resolution"])
    image = bpy.data.images.new(f"stpm bake {job['key']}", res, res, alpha=False, float_buffer=True)
    image.colorspace_settings.name = _working(bpy) if job["kind"] == "color" else "Non-Color"
    for i, slot in enumerate(obj.material_slots):
        m = slot.material
        if m is None or m.node_tree is None:
            slot.material = m = scratch["material"]
        _active_image_node(bpy, m, image if m == mat else scratch["image"])
    if not len(obj.material_slots):
        raise RuntimeError(f"object {obj.name!r} has no material slot")
    # Bake
    for o in view_layer.objects:
        if o.select_get(view_layer=view_layer):
            o.select_set(False, view_layer=view_layer)
    obj.hide_select = False
    obj.hide_viewport = False
    obj.hide_set(False, view_layer=view_layer)
    obj.select_set(True, view_layer=view_layer)
    view_layer.objects.active = obj
    margin = max(4, res // 64)
    bake = scene.render.bake
    bake.margin, bake.margin_type, bake.use_clear, bake.target = margin, "EXTEND", True, "IMAGE_TEXTURES"
    bake.use_selected_to_active = False
    with bpy.context.temp_override(scene=scene, view_layer=view_layer, active_object=obj, object=obj,
                                   selected_objects=[obj], selected_editable_objects=[obj]):
        got = bpy.ops.object.bake(type="EMIT", uv_layer=job["uv_map"], margin=margin, margin_type="EXTEND",
                                  use_clear=True, target="IMAGE_TEXTURES", use_selected_to_active=False)
    if "FINISHED" not in got:
        raise RuntimeError(f"the bake operator returned {sorted(got)}")
    # Write the EXR (32-bit float) and its note
    path = job["path"]
    tmp = path[:-4] + f".tmp{os.getpid()}.exr"
    image.save_render(tmp, scene=scene)          # Image.save() would apply the display transform
    os.replace(tmp, path)
    note = {k: job[k] for k in ("object", "material", "node", "socket", "kind", "uv_map", "resolution", "label")}
    note.update(blend=scene.name, frame=scene.frame_current, samples=samples, margin=margin,
                blender=bpy.app.version_string, time=time.strftime("%Y-%m-%d %H:%M:%S"))
    with open(path[:-4] + ".json", "w", encoding="utf-8") as f:
        json.dump(note, f, indent=1)
    bpy.data.images.remove(image)


def _world_child():
    """The world job (``world_bake_child.py`` beside this script; a job with ``"type": "world"``)."""
    import importlib.util
    here = os.path.dirname(os.path.abspath(globals().get("__file__") or sys.argv[0]))
    name = "stpm_world_bake_child"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, os.path.join(here, "world_bake_child.py"))
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        sys.modules[name] = mod
    return sys.modules[name]


def main() -> int:
    with open(_spec_path(), encoding="utf-8") as f:
        spec = json.load(f)
    import bpy
    if os.path.realpath(bpy.data.filepath or "") != os.path.realpath(spec["blend"]):
        bpy.ops.wm.open_mainfile(filepath=spec["blend"], load_ui=False)
    scene = bpy.data.scenes.get(spec["scene"]) or bpy.context.scene
    window = getattr(bpy.context, "window", None)
    if window is not None and window.scene != scene:
        window.scene = scene
    view_layer = scene.view_layers.get(spec["view_layer"]) or scene.view_layers[0]
    if window is not None and window.view_layer != view_layer:
        window.view_layer = view_layer
    _render_visibility(bpy, view_layer)
    frame = float(spec["frame"])
    scene.frame_set(int(frame // 1), subframe=frame - frame // 1)
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(spec["samples"])
    for name, value in (("use_adaptive_sampling", False), ("use_denoising", False), ("use_bake_denoising", False)):
        if hasattr(cy, name):
            setattr(cy, name, value)
    _linear_exr(scene.render.image_settings)
    scratch_img = bpy.data.images.new("stpm bake scratch", 8, 8, alpha=False, float_buffer=True)
    scratch_mat = bpy.data.materials.new("stpm bake scratch")
    scratch = {"image": scratch_img, "material": scratch_mat}
    results = []
    for job in spec["jobs"]:
        t0 = time.perf_counter()
        try:
            if job.get("type") == "world":
                note = _world_child().bake_world(bpy, job, frame, _linear_exr)
                results.append({"key": job["key"], "ok": True, "seconds": time.perf_counter() - t0})
                print(f"baked {job['label']} in {time.perf_counter() - t0:.2f} s "
                      f"(refined {len(note['refined'])} crop(s))", flush=True)
            else:
                _bake(bpy, scene, view_layer, job, int(spec["samples"]), scratch)
                results.append({"key": job["key"], "ok": True, "seconds": time.perf_counter() - t0})
                print(f"baked {job['label']} of {job['material']!r} on {job['object']!r} in "
                      f"{time.perf_counter() - t0:.2f} s", flush=True)
        except Exception as e:  # noqa: BLE001 -- one failed job must not stop the others
            traceback.print_exc()
            first = (str(e).strip().splitlines() or [""])[0]
            results.append({"key": job["key"], "ok": False, "seconds": time.perf_counter() - t0,
                            "error": f"{type(e).__name__}: {first}"})
        with open(spec["result"], "w", encoding="utf-8") as f:
            json.dump(results, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
