"""Blender world -> :class:`stpm_core.scene.World` (a constant environment: background and light)."""
from __future__ import annotations

import numpy as np

from .._core import scene_model
from .materials import linear_rgb


def _uses_nodes(idblock) -> bool:
    """Blender < 5 has a use_nodes switch; 5.0 always uses the node tree (and deprecates the flag)."""
    import bpy
    if bpy.app.version >= (5, 0, 0):
        return idblock.node_tree is not None
    return bool(idblock.use_nodes)


def _output_node(tree):
    """The active World Output node of a node tree, or None."""
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    active = [n for n in outs if getattr(n, "is_active_output", False)]
    return (active or outs or [None])[0]


def export_world(world, warnings: list) -> "scene_model.World":
    """Background colour * strength from the Background node (or ``world.color``).

    The core lights the scene with it as a constant environment (stpm_core/world_light.py), as
    Cycles does.  An Environment Texture on the colour becomes its mean radiance over the sphere
    (:func:`environment_mean`); other textures fall back to the node's own colour (both warned).
    """
    return _export_world(world, warnings)


def _export_world(world, warnings: list) -> "scene_model.World":
    if world is None:
        return scene_model.World(color=np.zeros(3), strength=1.0)
    tree = world.node_tree if _uses_nodes(world) else None
    if tree is None:
        return scene_model.World(color=np.array(world.color[:3], dtype=np.float64), strength=1.0)
    out = _output_node(tree)
    sock = out.inputs.get("Surface") if out is not None else None
    if sock is None or not sock.is_linked:
        return scene_model.World(color=np.zeros(3), strength=1.0)
    node = sock.links[0].from_node
    if node.bl_idname != "ShaderNodeBackground":
        warnings.append(f"world {world.name!r}: {node.bl_idname} is not supported, using black")
        return scene_model.World(color=np.zeros(3), strength=1.0)
    color_in, strength_in = node.inputs["Color"], node.inputs["Strength"]
    color = np.maximum(np.array(color_in.default_value[:3], dtype=np.float64), 0.0)
    if color_in.is_linked:
        src = color_in.links[0].from_node
        image = getattr(src, "image", None) if src.bl_idname == "ShaderNodeTexEnvironment" else None
        if src.bl_idname != "ShaderNodeTexEnvironment":
            warnings.append(f"world {world.name!r}: {src.bl_idname} on the background is not supported, using "
                            f"the Background node's own colour")
        elif image is None or image.size[0] * image.size[1] == 0 or image.channels < 3:
            what = "has no image" if image is None else f"image {image.name!r} could not be loaded"
            warnings.append(f"world {world.name!r}: the environment texture {what}, using the Background "
                            f"node's own colour")
        else:
            color = np.maximum(environment_mean(image), 0.0)
            warnings.append(f"world {world.name!r}: environment texture {image.name!r} is used as its mean "
                            f"radiance {np.round(color, 4).tolist()} (a constant sky: no sun spots, no "
                            f"reflections of the picture), as background and light")
    if strength_in.is_linked:
        warnings.append(f"world {world.name!r}: linked background strength is not supported, using its default value")
    return scene_model.World(color=color, strength=max(float(strength_in.default_value), 0.0))


def environment_mean(image, max_rows: int = 512) -> np.ndarray:
    """Mean radiance (3,) over the sphere of an equirectangular environment image (linear RGB).

    Row y (of h, bottom-up) spans latitude ``phi = -pi/2 + pi (y + 1/2) / h``; a pixel's solid
    angle is proportional to cos(phi), so the mean over directions is
    ``sum_y cos(phi_y) rowmean_y / sum_y cos(phi_y)``.  At most ``max_rows`` rows (evenly
    strided) are averaged, each over all its pixels; 8-bit sRGB images are linearised.
    """
    w, h = image.size[:]
    c = image.channels
    px = np.empty(w * h * c, dtype=np.float32)
    image.pixels.foreach_get(px)
    rows = np.unique(np.linspace(0, h - 1, min(h, max_rows)).round().astype(np.int64))
    rgb = px.reshape(h, w, c)[rows, :, :3]
    del px
    rgb = linear_rgb(rgb, image)
    weight = np.cos(-0.5 * np.pi + np.pi * (rows + 0.5) / h)
    return (weight[:, None] * rgb.mean(axis=1, dtype=np.float64)).sum(axis=0) / weight.sum()
