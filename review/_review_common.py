"""What the artist-review scripts in review/ share (bpy 5.0.1).

The scene builders (make_*.py, coat_layer_probe.py) make their scenes the way an artist would, with
bpy operators; the steps two or more of them take the same way live here once: an empty scene with
the STPM add-on, PNG/EXR textures written with OpenImageIO, Smart UV Project, Principled / Emission /
Glass / image-textured materials, boxes, lathed (Screw modifier) profiles, a Geometry Nodes scatter,
a two-bone armature bending a mesh, the outdoor review's car paint. The render scripts share the F12
set-up and report (render_*_bpy.py), Cycles' unbiased reference settings (render_*_cycles.py and the
probes) and a multilayer-EXR reader.

Import it from a script in review/ (run as ``python review/make_x.py``, so review/ is on sys.path):
``from _review_common import start_scene, principled, ...``. (Not named _common: blend_scenes/_common.py, the generators' helpers, is on sys.path too when
tests/test_addon_scenes.py is imported, as review/motion_probe.py does.)
"""
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import bpy
import OpenImageIO as oiio

HERE = Path(__file__).resolve().parent          # review/
ROOT = HERE.parent                              # the checkout
OUT = HERE / "out"                              # where the builders write .blend files and textures
TEX = ROOT / "blend_scenes" / "textures"        # the repository's texture images


def start_scene(frame_range=None, *, addon_from_path=False):
    """Blender's empty factory scene with the STPM add-on registered; new keyframes LINEAR.

    frame_range : (start, end) frames or None (Blender's 1-250).
    addon_from_path : False puts this checkout first on sys.path, so its add-on and stpm_core are the
        ones used; True leaves sys.path alone, so PYTHONPATH (or the installed package) decides, and
        a probe can measure another checkout's code on the same scene.
    Returns bpy.context.scene."""
    if not addon_from_path:
        sys.path.insert(0, str(ROOT))
    import addon
    OUT.mkdir(exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
    scene = bpy.context.scene
    if frame_range is not None:
        scene.frame_start, scene.frame_end = frame_range
    return scene


def write_image(path, arr, fmt="uint8"):
    """Write arr (h, w, c) float to path: fmt "uint8" clips to [0, 1] and rounds to 8 bits, "float"
    writes the values as they are (an EXR)."""
    h, w, c = arr.shape
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, c, fmt))
    buf.set_pixels(oiio.ROI(), arr if fmt == "float" else (np.clip(arr, 0, 1) * 255 + 0.5).astype(np.uint8))
    assert buf.write(str(path)), buf.geterror()


def select_only(obj):
    """Make obj the active and only selected object (what the operators below act on)."""
    bpy.context.view_layer.objects.active = obj
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)


def smart_uv(obj):
    """UV-unwrap all of obj's mesh with Smart UV Project."""
    select_only(obj)
    bpy.ops.object.mode_set(mode="EDIT"); bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(); bpy.ops.object.mode_set(mode="OBJECT")


def subdivide(obj, cuts):
    """Cut every edge of obj's mesh `cuts` times (Edit Mode > Subdivide)."""
    select_only(obj)
    bpy.ops.object.mode_set(mode="EDIT"); bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.subdivide(number_cuts=cuts); bpy.ops.object.mode_set(mode="OBJECT")


def principled(name, **inputs):
    """A new material with its Principled BSDF's inputs set: Base_Color=(r, g, b[, a]) sets
    "Base Color" (underscores stand for spaces; an RGB triple gets alpha 1). Returns (material, bsdf)."""
    m = bpy.data.materials.new(name)
    b = m.node_tree.nodes["Principled BSDF"]
    for k, v in inputs.items():
        b.inputs[k.replace("_", " ")].default_value = (*v, 1.0) if isinstance(v, tuple) and len(v) == 3 else v
    return m, b


def _replace_principled(name, idname):
    """A new material whose Principled BSDF is replaced by a new node of type idname, linked to the
    output's Surface. Returns (material, node)."""
    m = bpy.data.materials.new(name); nt = m.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    n = nt.nodes.new(idname)
    nt.links.new(n.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    return m, n


def emission(name, color, strength):
    """A material of an Emission shader alone: color (r, g, b[, a]), strength Blender's Emission
    Strength. Returns the material."""
    m, e = _replace_principled(name, "ShaderNodeEmission")
    e.inputs["Color"].default_value = (*color, 1.0) if len(color) == 3 else color
    e.inputs["Strength"].default_value = strength
    return m


def glass(name, roughness=0.0, ior=None, color=None):
    """A material of a Glass BSDF alone; ior and color (r, g, b, a) left at Blender's defaults when
    None. Returns the material."""
    m, g = _replace_principled(name, "ShaderNodeBsdfGlass")
    if color is not None:
        g.inputs["Color"].default_value = color
    if ior is not None:
        g.inputs["IOR"].default_value = ior
    g.inputs["Roughness"].default_value = roughness
    return m


def image_material(name, path, normal_path=None, *, scale=1.0, roughness=0.5, normal_strength=None):
    """A Principled material whose Base Color is the image at path (and whose Normal is a Normal Map
    of the Non-Color image at normal_path if given), through a Mapping scaled by `scale` on the UVs
    when scale != 1. normal_strength None leaves the Normal Map's Strength at 1. Returns the material."""
    m, b = principled(name, Roughness=roughness)
    nt = m.node_tree
    t = nt.nodes.new("ShaderNodeTexImage"); t.image = bpy.data.images.load(str(path), check_existing=True)
    vec = None
    if scale != 1.0:
        tc = nt.nodes.new("ShaderNodeTexCoord"); mp = nt.nodes.new("ShaderNodeMapping")
        mp.inputs["Scale"].default_value = (scale, scale, scale)
        nt.links.new(tc.outputs["UV"], mp.inputs["Vector"]); nt.links.new(mp.outputs[0], t.inputs["Vector"])
        vec = mp.outputs[0]
    nt.links.new(t.outputs["Color"], b.inputs["Base Color"])
    if normal_path is not None:
        tn = nt.nodes.new("ShaderNodeTexImage"); tn.image = bpy.data.images.load(str(normal_path), check_existing=True)
        tn.image.colorspace_settings.name = "Non-Color"
        nm = nt.nodes.new("ShaderNodeNormalMap")
        if normal_strength is not None:
            nm.inputs["Strength"].default_value = normal_strength
        if vec is not None:
            nt.links.new(vec, tn.inputs["Vector"])
        nt.links.new(tn.outputs["Color"], nm.inputs["Color"]); nt.links.new(nm.outputs["Normal"], b.inputs["Normal"])
    return m


def box(name, size, loc, mat=None, coll=None):
    """A cube of the given (x, y, z) size (scale applied) centred at loc, with material mat, moved
    into collection coll when given. Returns the object."""
    bpy.ops.mesh.primitive_cube_add(size=1, location=loc); o = bpy.context.object; o.name = name
    o.scale = size; bpy.ops.object.transform_apply(scale=True)
    if mat:
        o.data.materials.append(mat)
    if coll:
        for c in o.users_collection:
            c.objects.unlink(o)
        coll.objects.link(o)
    return o


def lathe(name, profile, loc, steps=48):
    """A mesh from an (r, z) profile line turned about z by a Screw modifier (as artists lathe
    glasses), smooth shaded, at loc. Returns the object."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([(r, 0, z) for r, z in profile], [(i, i + 1) for i in range(len(profile) - 1)], [])
    o = bpy.data.objects.new(name, me); bpy.context.scene.collection.objects.link(o); o.location = loc
    sc = o.modifiers.new("Screw", "SCREW"); sc.steps = sc.render_steps = steps; sc.use_merge_vertices = True
    sc.use_smooth_shade = True
    return o


def scatter_tree(name, instance, keep_surface=False, random_scale=None):
    """A Geometry Nodes tree that scatters `instance` (an object, or a collection) on its input's
    faces: Distribute Points on Faces -> Instance on Points, each instance scaled by a random vector
    between random_scale = ((min x, y, z), (max x, y, z)) when given, joined with the input surface
    when keep_surface. Returns (tree, distribute node) for the caller to set the density."""
    tree = bpy.data.node_groups.new(name, "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n = tree.nodes; gi = n.new("NodeGroupInput"); go = n.new("NodeGroupOutput")
    dist = n.new("GeometryNodeDistributePointsOnFaces")
    if isinstance(instance, bpy.types.Collection):
        info = n.new("GeometryNodeCollectionInfo"); info.inputs["Collection"].default_value = instance
        geometry = info.outputs["Instances"]
    else:
        info = n.new("GeometryNodeObjectInfo"); info.inputs["Object"].default_value = instance
        geometry = info.outputs["Geometry"]
    inst = n.new("GeometryNodeInstanceOnPoints")
    if random_scale is not None:
        rnd = n.new("FunctionNodeRandomValue"); rnd.data_type = "FLOAT_VECTOR"
        rnd.inputs["Min"].default_value, rnd.inputs["Max"].default_value = random_scale
    tree.links.new(gi.outputs[0], dist.inputs["Mesh"]); tree.links.new(dist.outputs["Points"], inst.inputs["Points"])
    tree.links.new(geometry, inst.inputs["Instance"])
    if random_scale is not None:
        tree.links.new(rnd.outputs["Value"], inst.inputs["Scale"])
    if keep_surface:
        join = n.new("GeometryNodeJoinGeometry")
        tree.links.new(inst.outputs[0], join.inputs[0]); tree.links.new(gi.outputs[0], join.inputs[0])
        tree.links.new(join.outputs[0], go.inputs[0])
    else:
        tree.links.new(inst.outputs[0], go.inputs[0])
    return tree, dist


def bend_rig(obj, name, loc, height, keys):
    """Bend obj with a keyframed armature: two bones "Low" (0 to height/2 up z) and "High" (on to
    height) of an armature object `name` at loc, obj parented with automatic weights; "High" rotates
    about x through keys, (frame, degrees) pairs. Returns the armature object."""
    arm_d = bpy.data.armatures.new(name); rig = bpy.data.objects.new(name, arm_d)
    bpy.context.scene.collection.objects.link(rig); rig.location = loc
    select_only(rig); bpy.ops.object.mode_set(mode="EDIT")
    b1 = arm_d.edit_bones.new("Low"); b1.head = (0, 0, 0); b1.tail = (0, 0, height / 2)
    b2 = arm_d.edit_bones.new("High"); b2.head = (0, 0, height / 2); b2.tail = (0, 0, height); b2.parent = b1
    bpy.ops.object.mode_set(mode="OBJECT")
    for o in (obj, rig):
        o.select_set(True)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.parent_set(type="ARMATURE_AUTO")
    pb = rig.pose.bones["High"]; pb.rotation_mode = "XYZ"
    for f, a in keys:
        pb.rotation_euler.x = math.radians(a); pb.keyframe_insert("rotation_euler", index=0, frame=f)
    return rig


def open_for_f12(blend, preset, samples=None):
    """Open blend as the artist's F12 scripts do: the STPM add-on registered (this checkout's), STPM
    the engine, the preset applied (bpy.ops.stpm.apply_preset) and samples, when given, overriding
    the preset's. Returns the scene."""
    sys.path.insert(0, str(ROOT))
    import addon
    addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    s = bpy.context.scene
    s.render.engine = "STPM"
    bpy.ops.stpm.apply_preset(preset=preset)
    if samples:
        s.stpm.samples = samples
    return s


def print_f12_report(wall, *, errors=False):
    """Print what the add-on reported of its last render: the wall time (s), its warnings (and its
    errors and report keys when errors), the passes written and the stats' phases as JSON."""
    from addon.engine import LAST_RENDER
    st = LAST_RENDER.get("stats", {})
    print(f"F12 wall {wall:.1f} s")
    for w in LAST_RENDER.get("warnings", []):
        print("WARNING:", w)
    if errors:
        for e in LAST_RENDER.get("errors", []) if isinstance(LAST_RENDER.get("errors"), list) else []:
            print("ERROR:", e)
        print("LAST_RENDER keys:", sorted(LAST_RENDER))
    print("passes:", LAST_RENDER.get("passes"))
    print(json.dumps({k: st.get(k) for k in ("export_s", "photon_trace_s", "photon_map_build_s", "render_s",
                                             "render_wall_s", "photons_global", "photons_caustic", "samples")}))


def unbiased_cycles(scene, spp):
    """Render scene with Cycles as the review's references do: CPU, spp samples, no denoising, no
    adaptive sampling, no clamping (Cycles' unbiased answer; bounces left as the file has them).
    Returns scene.cycles for further settings."""
    scene.render.engine = "CYCLES"; cy = scene.cycles
    cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", spp, False, False
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    return cy


def cycles_reference(blend, frame, out_stem, args):
    """The review's Cycles reference of blend at frame: args = SPP [TAG] [--seed N] [--time-limit S]
    (TAG defaults to SPP, seed to 0), unbiased_cycles' settings, a 32-bit EXR written to
    review/out/<out_stem>_<TAG>.exr; prints the wall time."""
    spp = int(args[0]); tag = args[1] if len(args) > 1 and not args[1].startswith("--") else str(spp)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    s = bpy.context.scene; s.frame_set(frame)
    cy = unbiased_cycles(s, spp)
    cy.seed = int(args[args.index("--seed") + 1]) if "--seed" in args else 0
    if "--time-limit" in args:
        cy.time_limit = float(args[args.index("--time-limit") + 1])
    s.render.image_settings.media_type = "IMAGE"; s.render.image_settings.file_format = "OPEN_EXR"
    s.render.image_settings.color_depth = "32"
    s.render.filepath = str(OUT / f"{out_stem}_{tag}.exr"); s.render.use_file_extension = False
    t = time.time(); bpy.ops.render.render(write_still=True); print(f"cycles {spp} spp wall {time.time() - t:.1f} s")


def read_exr_layers(path):
    """Every channel of an EXR, all its subimages (a multilayer EXR's layers): {channel name: (h, w)
    float32}, e.g. "ViewLayer.Combined.R", "ViewLayer.Object Index.X"."""
    inp = oiio.ImageInput.open(str(path)); sub = 0; ch = {}
    while inp.seek_subimage(sub, 0):
        sp = inp.spec(); px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, -1)
        ch.update({n: px[..., i] for i, n in enumerate(sp.channelnames)}); sub += 1
    inp.close()
    return ch


def car_paint(name="CarPaint", coat_weight=1.0):
    """The outdoor review's car paint: Principled base (0.55, 0.02, 0.02), Metallic 0.7, a Noise
    texture at scale 600 through a ramp (0.15 to 0.45) into Roughness and a Bump (0.15) into Normal,
    Coat Weight coat_weight, Coat Roughness 0.03. Returns the material."""
    paint, pb = principled(name, Base_Color=(0.55, 0.02, 0.02), Metallic=0.7, Roughness=0.3,
                           Coat_Weight=coat_weight, Coat_Roughness=0.03)
    nt = paint.node_tree
    flakes = nt.nodes.new("ShaderNodeTexNoise"); flakes.inputs["Scale"].default_value = 600.0
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position = 0.45; ramp.color_ramp.elements[0].color = (0.15, 0.15, 0.15, 1)
    ramp.color_ramp.elements[1].position = 0.55; ramp.color_ramp.elements[1].color = (0.45, 0.45, 0.45, 1)
    nt.links.new(flakes.outputs["Fac"], ramp.inputs["Fac"]); nt.links.new(ramp.outputs["Color"], pb.inputs["Roughness"])
    bump = nt.nodes.new("ShaderNodeBump"); bump.inputs["Strength"].default_value = 0.15
    nt.links.new(flakes.outputs["Fac"], bump.inputs["Height"]); nt.links.new(bump.outputs["Normal"], pb.inputs["Normal"])
    return paint


def car_body(location, paint):
    """The outdoor review's car: a UV sphere of radius 0.5 scaled (1.6, 0.8, 0.55), smooth, named
    CarBody, with material paint. Returns the object."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=location, segments=48, ring_count=24)
    car = bpy.context.object; car.name = "CarBody"; car.scale = (1.6, 0.8, 0.55)
    bpy.ops.object.shade_smooth()
    car.data.materials.append(paint)
    return car
