"""The world job of the bake child (:mod:`.bake_child`): render a world alone with Cycles into an
equirectangular image (standalone: imports nothing of the add-on; ``bpy`` and ``numpy`` are passed
in or imported here, inside the child).

A job (:class:`addon.export.world.WorldJob` as a dict) names the world, the view ("light" or
"camera"), the resolution (W, H), the samples and the refinement settings.  In a new scene that
holds only a panoramic camera (so no object is rendered), with the job's world:

* the camera: type PANO, equirectangular, full latitude / longitude range, at the origin, turned
  by :data:`PANO_ROTATION` so that image pixel (u, v) is the direction Cycles' Environment Texture
  maps to (u, v): ``u = (pi - atan2(y, x)) / (2 pi)``, ``v = 1 - acos(z) / pi`` (checked by
  baking an Environment Texture world and comparing with its image, tests/test_world_bake.py);
* Cycles on the CPU, ``samples`` samples, box pixel filter 1 pixel wide (each pixel is the mean
  radiance over its (u, v) cell), no adaptive sampling, no denoising, no clamping, seed 0;
* the "light" view first replaces, in a copy of the world (node groups copied too), every link
  from a Light Path node's "Is Camera Ray" output by a Value node 0;
* pixels carrying more than ``refine_share`` of the image's power (a sun disc a pixel or two
  wide, whose coverage 16 samples estimate to a few per cent) are rendered again: at most
  :data:`MAX_REFINE_BOXES` crops (render border) around them, margin :data:`REFINE_MARGIN`
  pixels, at up to ``refine_samples`` samples, pasted into the image;
* the image is written as a 32-bit float RGB OpenEXR, linear in the working space (colour management
  overridden), renamed into place as ``job["path"]``, with a ``.json`` note beside it.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import time

PANO_ROTATION = (math.pi / 2, 0.0, -math.pi / 2)     # camera looks along +X, +Z up: u = 0.5 is +X
MAX_REFINE_BOXES = 4
REFINE_MARGIN = 2
REFINE_BUDGET = 1 << 22          # samples x pixels of one crop at most
MAX_HOT_PIXELS = 4096


def _world(bpy, name: str):
    for w in bpy.data.worlds:
        if w.name_full == name or w.name == name:
            return w
    raise RuntimeError(f"world {name!r} not found in the copy")


def _has_camera_ray(tree, memo: dict) -> bool:
    key = tree.as_pointer()
    if key in memo:
        return memo[key]
    memo[key] = False
    found = False
    for n in tree.nodes:
        if n.bl_idname == "ShaderNodeLightPath" and n.outputs["Is Camera Ray"].is_linked:
            found = True
        elif n.bl_idname == "ShaderNodeGroup" and n.node_tree is not None and _has_camera_ray(n.node_tree, memo):
            found = True
    memo[key] = found
    return found


def zero_camera_ray(tree, memo=None, copies=None) -> int:
    """Replace every link from a Light Path "Is Camera Ray" output of ``tree`` (and of the node
    groups it uses, copied first) by a Value node 0; returns the links replaced."""
    memo = {} if memo is None else memo
    copies = {} if copies is None else copies
    done = 0
    for n in list(tree.nodes):
        if n.bl_idname == "ShaderNodeLightPath":
            out = n.outputs["Is Camera Ray"]
            for lk in list(out.links):
                to = lk.to_socket
                val = tree.nodes.new("ShaderNodeValue")
                val.name = val.label = "stpm bake: Is Camera Ray = 0"
                val.outputs[0].default_value = 0.0
                tree.links.remove(lk)
                tree.links.new(val.outputs[0], to)
                done += 1
        elif n.bl_idname == "ShaderNodeGroup" and n.node_tree is not None and _has_camera_ray(n.node_tree, memo):
            orig = n.node_tree
            if orig.as_pointer() not in copies:
                cp = orig.copy()
                copies[orig.as_pointer()] = cp
                done += zero_camera_ray(cp, memo, copies)
            n.node_tree = copies[orig.as_pointer()]
    return done


def _setup(bpy, world, job: dict, frame: float):
    """A new scene holding only the panoramic camera, rendering ``world``."""
    W, H = (int(x) for x in job["resolution"])
    scene = bpy.data.scenes.new("stpm world bake")
    scene.world = world
    cam = bpy.data.cameras.new("stpm world bake")
    cam.type = "PANO"
    if hasattr(cam, "panorama_type"):
        cam.panorama_type = "EQUIRECTANGULAR"
    else:                                               # Blender < 4.0
        cam.cycles.panorama_type = "EQUIRECTANGULAR"
    holder = cam if hasattr(cam, "latitude_min") else cam.cycles
    holder.latitude_min, holder.latitude_max = -math.pi / 2, math.pi / 2
    holder.longitude_min, holder.longitude_max = -math.pi, math.pi
    cam.clip_start, cam.clip_end = 1e-3, 1e6
    obj = bpy.data.objects.new("stpm world bake", cam)
    obj.location = (0.0, 0.0, 0.0)
    obj.rotation_mode = "XYZ"
    obj.rotation_euler = PANO_ROTATION
    scene.collection.objects.link(obj)
    scene.camera = obj
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = W, H, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_border = False
    r.film_transparent = False
    r.use_motion_blur = False
    for name in ("use_compositing", "use_sequencer", "use_freestyle"):
        if hasattr(r, name):
            setattr(r, name, False)
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(job["samples"])
    for name, value in (("use_adaptive_sampling", False), ("use_denoising", False), ("seed", 0),
                        ("use_animated_seed", False), ("pixel_filter_type", "BOX"), ("filter_width", 1.0),
                        ("sample_clamp_direct", 0.0), ("sample_clamp_indirect", 0.0), ("film_exposure", 1.0),
                        ("time_limit", 0.0)):
        if hasattr(cy, name):
            setattr(cy, name, value)
    scene.view_settings.exposure = 0.0
    vis = getattr(world, "visibility", None)
    if vis is not None and hasattr(vis, "camera"):
        vis.camera = True                                # the bake is the world's radiance
    scene.frame_set(int(frame // 1), subframe=frame - frame // 1)
    return scene, obj, cam


def _render(bpy, scene, path: str) -> None:
    scene.render.filepath = path
    got = bpy.ops.render.render(write_still=True, scene=scene.name)
    if "FINISHED" not in got or not os.path.isfile(path):
        raise RuntimeError(f"the Cycles render returned {sorted(got)} and wrote no image")


def _load(bpy, np, path: str, W: int, H: int):
    """(H, W, 3) float32 of a rendered EXR, row 0 at the bottom."""
    img = bpy.data.images.load(path, check_existing=False)
    try:
        w, h = img.size[:]
        c = img.channels
        if (w, h) != (W, H):
            raise RuntimeError(f"the render is {w}x{h}, not {W}x{H}")
        px = np.empty(w * h * c, np.float32)
        img.pixels.foreach_get(px)
        return px.reshape(h, w, c)[:, :, :3].copy()
    finally:
        bpy.data.images.remove(img)


def hot_boxes(np, px, share: float, margin: int = REFINE_MARGIN, max_boxes: int = MAX_REFINE_BOXES) -> list:
    """Boxes (x0, y0, x1, y1), rows bottom-up, around the pixels carrying more than ``share`` of the
    image's power (luminance x solid angle), brightest first; clusters of pixels closer than
    2 ``margin`` share a box."""
    H, W = px.shape[:2]
    lum = np.maximum(px.max(axis=2).astype(np.float64), 0.0)
    w = np.sin(math.pi * (np.arange(H) + 0.5) / H)[:, None]
    power = lum * w
    total = float(power.sum())
    if not total > 0.0 or not math.isfinite(total):
        return []
    hot = np.argwhere(power > share * total)
    if len(hot) == 0:
        return []
    if len(hot) > MAX_HOT_PIXELS:
        order = np.argsort(-power[hot[:, 0], hot[:, 1]])[:MAX_HOT_PIXELS]
        hot = hot[order]
    cells = {(int(y), int(x)) for y, x in hot}
    seen, clusters = set(), []
    reach = 2 * margin
    for start in cells:
        if start in seen:
            continue
        seen.add(start)
        stack, members = [start], []
        while stack:
            y, x = stack.pop()
            members.append((y, x))
            for dy in range(-reach, reach + 1):
                for dx in range(-reach, reach + 1):
                    q = (y + dy, x + dx)
                    if q in cells and q not in seen:
                        seen.add(q)
                        stack.append(q)
        ys = [m[0] for m in members]
        xs = [m[1] for m in members]
        e = float(sum(power[m] for m in members))
        clusters.append((e, (max(min(xs) - margin, 0), max(min(ys) - margin, 0),
                             min(max(xs) + margin + 1, W), min(max(ys) + margin + 1, H))))
    clusters.sort(key=lambda c: -c[0])
    return [b for _e, b in clusters[:max_boxes]]


def _refine(bpy, np, scene, px, job: dict, tmp_dir: str) -> list:
    """Render the hot boxes again at more samples and paste them into ``px``; returns what was done."""
    H, W = px.shape[:2]
    done = []
    boxes = hot_boxes(np, px, float(job["refine_share"]))
    if not boxes:
        return done
    r, cy = scene.render, scene.cycles
    base = cy.samples
    r.use_border, r.use_crop_to_border = True, True
    try:
        for i, (x0, y0, x1, y1) in enumerate(boxes):
            area = (x1 - x0) * (y1 - y0)
            spp = int(min(int(job["refine_samples"]), max(base, REFINE_BUDGET // max(area, 1))))
            if spp <= base:
                continue
            r.border_min_x, r.border_max_x = x0 / W, x1 / W
            r.border_min_y, r.border_max_y = y0 / H, y1 / H
            cy.samples = spp
            path = os.path.join(tmp_dir, f"crop{i}.exr")
            _render(bpy, scene, path)
            img = bpy.data.images.load(path, check_existing=False)
            try:
                w, h = img.size[:]
                if (w, h) != (x1 - x0, y1 - y0):    # the border snapped differently: keep the first pass
                    continue
                c = img.channels
                crop = np.empty(w * h * c, np.float32)
                img.pixels.foreach_get(crop)
            finally:
                bpy.data.images.remove(img)
            px[y0:y1, x0:x1] = crop.reshape(h, w, c)[:, :, :3]
            done.append({"box": [x0, y0, x1, y1], "samples": spp})
    finally:
        r.use_border, r.use_crop_to_border = False, False
        cy.samples = base
    return done


def _save(bpy, np, scene, px, path: str, linear_exr) -> None:
    H, W = px.shape[:2]
    img = bpy.data.images.new("stpm world bake result", W, H, alpha=False, float_buffer=True)
    try:
        # the working space: the EXR holds scene-linear values, read back without conversion
        img.colorspace_settings.name = str(getattr(getattr(bpy.data, "colorspace", None), "working_space",
                                                   "Linear Rec.709"))
        rgba = np.ones((H, W, 4), np.float32)
        rgba[:, :, :3] = px
        img.pixels.foreach_set(rgba.ravel())
        linear_exr(scene.render.image_settings)
        img.save_render(path, scene=scene)
    finally:
        bpy.data.images.remove(img)


def bake_world(bpy, job: dict, frame: float, linear_exr) -> dict:
    """Bake one world job (module docstring); returns a note of what was done."""
    import numpy as np
    t0 = time.perf_counter()
    src = _world(bpy, job["world"])
    if src.node_tree is None:
        raise RuntimeError(f"world {src.name!r} has no node tree")
    view = job["view"]
    world, replaced = src, 0
    if view == "light":
        world = src.copy()
        world.name = "stpm world bake (light)"
        replaced = zero_camera_ray(world.node_tree)
    elif view != "camera":
        raise RuntimeError(f"unknown world view {view!r}")
    W, H = (int(x) for x in job["resolution"])
    path = job["path"]
    first = path[:-4] + f".tmp{os.getpid()}_first.exr"
    scene, obj, cam = _setup(bpy, world, job, frame)
    crops = tempfile.mkdtemp(prefix="stpm_world_bake_")
    refined = []
    try:
        linear_exr(scene.render.image_settings)
        _render(bpy, scene, first)
        px = _load(bpy, np, first, W, H)
        refined = _refine(bpy, np, scene, px, job, crops)
        if refined:
            out = path[:-4] + f".tmp{os.getpid()}.exr"
            _save(bpy, np, scene, px, out, linear_exr)
            os.replace(out, path)
        else:
            os.replace(first, path)
    finally:
        if os.path.exists(first):
            os.unlink(first)
        shutil.rmtree(crops, ignore_errors=True)
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(obj)
        bpy.data.cameras.remove(cam)
        if world is not src:
            bpy.data.worlds.remove(world)
    note = {"world": src.name, "view": view, "resolution": [W, H], "samples": int(job["samples"]),
            "refined": refined, "camera_ray_links_zeroed": replaced, "frame": frame,
            "pano_rotation": list(PANO_ROTATION), "blender": bpy.app.version_string,
            "seconds": round(time.perf_counter() - t0, 3), "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    with open(path[:-4] + ".json", "w", encoding="utf-8") as f:
        json.dump(note, f, indent=1)
    return note
