"""Procedural textures (stpm_core.kernels.procedural) against Cycles 5.0 itself, texel by texel.

Reference values come from real Cycles renders (bpy 5.0, CPU, SVM): each case is a 2 x 2 plane
whose material feeds the texture node with *exact* coordinates and writes its outputs into
shader AOVs (``v0``, ``v1`` values, ``c0``, ``c1`` colours) of a 32-bit multilayer EXR; the
Emission / Combined pass is not used, so outputs are stored unclamped and unshaded.

Exact coordinates: the Object coordinate is snapped to the pixel grid (Vector Math SNAP to 1/16, a
pixel is 1/16 of the plane) plus half a pixel: every camera sample of a pixel gives the same
dyadic pixel-centre value, whatever Cycles' sub-pixel jitter and ray-hit rounding do (Box filter
0.01 px keeps samples well inside the pixel).  From the snapped (x, y) the material forms

    X = x + ox,   Y = y + oy,   Z = 0.5 x - 0.25 y + oz,   W = 0.75 x + 0.375 y + ow

with dyadic offsets, all exact in float32; the test evaluates the numba functions at the same
values (and at the node's float32 parameter values, read back from the sockets).  Several cases
share one render: one plane (32 x 32 pixels) per case, side by side.

Also: the integer hashes (lookup3, PCG) against a pure-Python implementation written separately
here (Python ints, explicit 32-bit wrap-around).  The Cycles tests skip themselves without bpy /
OpenImageIO; the hash tests need neither.  Tolerances and measured errors: ``_tolerance``.
"""
from __future__ import annotations

import struct

import numpy as np
import pytest

from stpm_core.kernels import procedural as P

PIX = 32                      # pixels per plane side
COLS = 8                      # planes per row of a render
OFFS = (0.375, -0.625, 0.25, 0.8125)    # ox, oy, oz, ow (dyadic)


# ----------------------------------------------------------------------------
# Pure-Python hashes (independent of the module's int64 / numba code)
# ----------------------------------------------------------------------------
def _u(v):
    return v % (1 << 32)


def _rotl(x, k):
    return _u((x << k) | (x >> (32 - k)))


def py_final(a, b, c):
    for (x, y, k) in (("c", "b", 14), ("a", "c", 11), ("b", "a", 25), ("c", "b", 16),
                      ("a", "c", 4), ("b", "a", 14), ("c", "b", 24)):
        regs = {"a": a, "b": b, "c": c}
        regs[x] = _u((regs[x] ^ regs[y]) - _rotl(regs[y], k))
        a, b, c = regs["a"], regs["b"], regs["c"]
    return c


def py_mix(a, b, c):
    regs = {"a": a, "b": b, "c": c}
    for (x, y, z, k) in (("a", "c", "b", 4), ("b", "a", "c", 6), ("c", "b", "a", 8),
                         ("a", "c", "b", 16), ("b", "a", "c", 19), ("c", "b", "a", 4)):
        regs[x] = _u(regs[x] - regs[y]) ^ _rotl(regs[y], k)
        regs[y] = _u(regs[y] + regs[z])
    return regs["a"], regs["b"], regs["c"]


def py_hash(*keys):
    """Cycles' hash_uint / hash_uint2 / 3 / 4 of unsigned 32-bit keys."""
    n = len(keys)
    init = _u(0xDEADBEEF + (n << 2) + 13)
    a = b = c = init
    ks = [_u(k) for k in keys]
    if n == 4:
        a, b, c = _u(a + ks[0]), _u(b + ks[1]), _u(c + ks[2])
        a, b, c = py_mix(a, b, c)
        a = _u(a + ks[3])
    else:
        a = _u(a + ks[0])
        if n >= 2:
            b = _u(b + ks[1])
        if n >= 3:
            c = _u(c + ks[2])
    return py_final(a, b, c)


def py_bits(f):
    return struct.unpack("<I", struct.pack("<f", f))[0]


def py_hash_float(*fs):
    """hash_float{,2,3,4}_to_float: float32(hash) * 2^-32 (float32 arithmetic of Cycles)."""
    return float(np.float32(py_hash(*[py_bits(f) for f in fs]))) / 4294967296.0


def _i32(v):
    v = _u(v)
    return v - (1 << 32) if v >= (1 << 31) else v


def py_pcg(*v):
    """Cycles' hash_pcg{2,3,4}d_i on signed 32-bit ints (C wrap-around, arithmetic >>)."""
    v = [_i32(_i32(x * 1664525) + 1013904223) for x in v]
    n = len(v)

    def rounds(v):
        v = list(v)
        if n == 2:
            v[0] = _i32(v[0] + v[1] * 1664525)
            v[1] = _i32(v[1] + v[0] * 1664525)
        elif n == 3:
            v[0] = _i32(v[0] + v[1] * v[2])
            v[1] = _i32(v[1] + v[2] * v[0])
            v[2] = _i32(v[2] + v[0] * v[1])
        else:
            v[0] = _i32(v[0] + v[1] * v[3])
            v[1] = _i32(v[1] + v[2] * v[0])
            v[2] = _i32(v[2] + v[0] * v[1])
            v[3] = _i32(v[3] + v[1] * v[2])
        return v
    v = rounds(v)
    v = [x ^ (x >> 16) for x in v]      # Python >> on negative ints is arithmetic, as C's on int
    v = rounds(v)
    return tuple(x & 0x7FFFFFFF for x in v)


_KEYS = [0, 1, 2, 13, 0x7FFFFFFF, 0x80000000, 0xDEADBEEF, 0xFFFFFFFF, 123456789, 3000000000]


def test_hash_uint_matches_pure_python():
    rng = np.random.default_rng(5)
    keys = _KEYS + [int(k) for k in rng.integers(0, 1 << 32, 40)]
    for i, k in enumerate(keys):
        k2, k3, k4 = keys[(i + 3) % len(keys)], keys[(i + 7) % len(keys)], keys[(i + 11) % len(keys)]
        assert P.hash_uint(k) == py_hash(k)
        assert P.hash_uint2(k, k2) == py_hash(k, k2)
        assert P.hash_uint3(k, k2, k3) == py_hash(k, k2, k3)
        assert P.hash_uint4(k, k2, k3, k4) == py_hash(k, k2, k3, k4)
    # negative ints hash as their unsigned 32-bit pattern (Cycles passes int lattice indices)
    assert P.hash_uint(-1) == py_hash(0xFFFFFFFF)
    assert P.hash_uint3(-5, 7, -123456) == py_hash(_u(-5), 7, _u(-123456))


def test_hash_float_bits_and_pcg_match_pure_python():
    floats = [0.0, -0.0, 1.0, -1.0, 0.5, 1e-30, 3.14159, -2.75, 1e6, 123.456, 1e-45]
    for i, f in enumerate(floats):
        g, h, q = floats[(i + 1) % len(floats)], floats[(i + 4) % len(floats)], floats[(i + 6) % len(floats)]
        assert P.float_bits(f) == py_bits(f)
        assert P.hash_float_to_float(f) == py_hash_float(f)
        assert P.hash_float2_to_float(f, g) == py_hash_float(f, g)
        assert P.hash_float3_to_float(f, g, h) == py_hash_float(f, g, h)
        assert P.hash_float4_to_float(f, g, h, q) == py_hash_float(f, g, h, q)
    rng = np.random.default_rng(9)
    ints = [0, 1, -1, 2147483647, -2147483648, 77, -300] + [int(v) for v in rng.integers(-2 ** 31, 2 ** 31, 30)]
    for i, v in enumerate(ints):
        w, x, y = ints[(i + 1) % len(ints)], ints[(i + 2) % len(ints)], ints[(i + 5) % len(ints)]
        assert P.hash_pcg2d(v, w) == py_pcg(v, w)
        assert P.hash_pcg3d(v, w, x) == py_pcg(v, w, x)
        assert P.hash_pcg4d(v, w, x, y) == py_pcg(v, w, x, y)


def test_white_noise_is_the_float_hash():
    v, r, g, b = P.white_noise_texture(0.25, -1.5, 3.0, 0.125, 3)
    assert v == r == py_hash_float(0.25, -1.5, 3.0)
    assert g == py_hash_float(0.25, -1.5, 3.0, 1.0) and b == py_hash_float(0.25, -1.5, 3.0, 2.0)
    v, r, g, b = P.white_noise_texture(0.25, -1.5, 3.0, 0.125, 4)
    assert v == py_hash_float(0.25, -1.5, 3.0, 0.125) and g == py_hash_float(3.0, 0.25, 0.125, -1.5)
    assert b == py_hash_float(0.125, 3.0, -1.5, 0.25)


def test_noise_without_colour_and_argument_types():
    args = (0.3, -0.4, 0.5, 0.25, 3, 5.0, 2.5, 0.5, 2.0, 0.3, True, P.NOISE_TYPES["FBM"])
    fac, r, g, b = P.noise_texture(*args)
    assert r == fac and g != fac and b != fac
    assert P.noise_texture(*args, 0.0, 1.0, False) == (fac, 0.0, 0.0, 0.0)
    # a jitted caller passing literal / narrow ints and float32 values re-specialises only the
    # thin public wrapper: the implementation keeps one (float64 / int64 / bool) signature
    from numba import njit

    @njit
    def call(x):
        return P.noise_texture(np.float32(x), -0.4, 0.5, 0.25, np.int32(3), 5.0, 2.5, 0.5, 2.0, 0.3, 1, 1)

    assert call(0.3) == P.noise_texture(float(np.float32(0.3)), *args[1:])
    assert len(P._noise_texture.signatures) <= 1      # 0 when the implementation came from numba's cache


def test_enum_dicts_cover_blender_identifiers():
    assert set(P.NOISE_TYPES) == {"MULTIFRACTAL", "FBM", "HYBRID_MULTIFRACTAL", "RIDGED_MULTIFRACTAL",
                                  "HETERO_TERRAIN"}
    assert set(P.VORONOI_FEATURES) == {"F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE", "N_SPHERE_RADIUS"}
    assert set(P.VORONOI_METRICS) == {"EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI"}
    assert set(P.WAVE_TYPES) == {"BANDS", "RINGS"} and set(P.WAVE_PROFILES) == {"SIN", "SAW", "TRI"}
    assert set(P.WAVE_BANDS_DIRECTIONS) == {"X", "Y", "Z", "DIAGONAL"}
    assert set(P.WAVE_RINGS_DIRECTIONS) == {"X", "Y", "Z", "SPHERICAL"}


# ----------------------------------------------------------------------------
# Cycles renders
# ----------------------------------------------------------------------------
def _read_multilayer(path):
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    out, i = {}, 0
    while inp.seek_subimage(i, 0):
        spec = inp.spec()
        px = inp.read_image(i, 0, 0, spec.nchannels, "float").reshape(spec.height, spec.width, spec.nchannels)
        for k, name in enumerate(spec.channelnames):
            out[name] = np.asarray(px[..., k], np.float64)
        i += 1
    inp.close()
    return out


def _coord_nodes(tree):
    """Nodes giving exact (X, Y, Z) (a Combine XYZ output) and W (a Math output)."""
    nodes, links = tree.nodes, tree.links
    tc = nodes.new("ShaderNodeTexCoord")
    snap = nodes.new("ShaderNodeVectorMath")
    snap.operation = "SNAP"
    snap.inputs[1].default_value = (1.0 / 16.0,) * 3
    half = nodes.new("ShaderNodeVectorMath")
    half.operation = "ADD"
    half.inputs[1].default_value = (1.0 / 32.0, 1.0 / 32.0, 0.0)
    links.new(tc.outputs["Object"], snap.inputs[0])
    links.new(snap.outputs[0], half.inputs[0])
    sep = nodes.new("ShaderNodeSeparateXYZ")
    links.new(half.outputs[0], sep.inputs[0])

    def madd(a, ka, b, kb, c):
        """a * ka + (b * kb + c): exact for our dyadic values."""
        inner = nodes.new("ShaderNodeMath")
        inner.operation = "MULTIPLY_ADD"
        links.new(b, inner.inputs[0])
        inner.inputs[1].default_value = kb
        inner.inputs[2].default_value = c
        outer = nodes.new("ShaderNodeMath")
        outer.operation = "MULTIPLY_ADD"
        links.new(a, outer.inputs[0])
        outer.inputs[1].default_value = ka
        links.new(inner.outputs[0], outer.inputs[2])
        return outer.outputs[0]

    x, y = sep.outputs[0], sep.outputs[1]
    comb = nodes.new("ShaderNodeCombineXYZ")
    links.new(madd(x, 1.0, y, 0.0, OFFS[0]), comb.inputs[0])
    links.new(madd(y, 1.0, x, 0.0, OFFS[1]), comb.inputs[1])
    links.new(madd(x, 0.5, y, -0.25, OFFS[2]), comb.inputs[2])
    return comb.outputs[0], madd(x, 0.75, y, 0.375, OFFS[3])


def _pixel_coords():
    """(PIX, PIX) arrays X, Y, Z, W of the pixel centres of one plane (row 0 = top)."""
    j = np.arange(PIX)
    x = -1.0 + (j + 0.5) / 16.0
    y = 1.0 - (j + 0.5) / 16.0
    X, Y = np.meshgrid(x, y)
    return X + OFFS[0], Y + OFFS[1], 0.5 * X - 0.25 * Y + OFFS[2], 0.75 * X + 0.375 * Y + OFFS[3]


def _sock(coll, name):
    """A node's socket by name, available or not (5.0's name look-up skips unavailable sockets)."""
    return next(s for s in coll if s.name == name)


AOVS = (("v0", "VALUE"), ("v1", "VALUE"), ("c0", "COLOR"), ("c1", "COLOR"))


def render_cases(cases, tmp_path, name="tex"):
    """Render each case (bl_idname, props, inputs, {output: aov}) on its own plane; per case a dict
    aov -> (PIX, PIX) or (PIX, PIX, 3) array, the input values and the properties read back from the node
    (float32 values, as Cycles sees them)."""
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    cy = sc.cycles
    cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", 1, False, False
    cy.pixel_filter_type, cy.filter_width = "BOX", 0.01
    cy.seed = 0
    n = len(cases)
    rows = (n + COLS - 1) // COLS
    cols = min(n, COLS)
    sc.render.resolution_x, sc.render.resolution_y = PIX * cols, PIX * rows
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    sc.world = world
    vl = sc.view_layers[0]
    for aname, atype in AOVS:
        aov = vl.aovs.add()
        aov.name, aov.type = aname, atype
    cam = bpy.data.cameras.new("cam")
    cam.type, cam.ortho_scale = "ORTHO", 2.0 * max(cols, rows)
    cam_ob = bpy.data.objects.new("cam", cam)
    cam_ob.location = (cols - 1.0, -(rows - 1.0), 5.0)
    sc.collection.objects.link(cam_ob)
    sc.camera = cam_ob
    nodes_out = []
    for idx, (idname, props, inputs, outputs) in enumerate(cases):
        me = bpy.data.meshes.new(f"plane{idx}")
        me.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
        ob = bpy.data.objects.new(f"plane{idx}", me)
        ob.location = (2.0 * (idx % COLS), -2.0 * (idx // COLS), 0.0)
        sc.collection.objects.link(ob)
        mat = bpy.data.materials.new(f"mat{idx}")
        tree = mat.node_tree
        for nd in list(tree.nodes):
            tree.nodes.remove(nd)
        tree.nodes.new("ShaderNodeOutputMaterial")
        vec, w = _coord_nodes(tree)
        tex = tree.nodes.new(idname)
        for k, v in props.items():
            setattr(tex, k, v)
        for k, v in inputs.items():
            _sock(tex.inputs, k).default_value = v
        tree.links.new(vec, _sock(tex.inputs, "Vector"))
        if any(s.name == "W" for s in tex.inputs):
            tree.links.new(w, _sock(tex.inputs, "W"))
        for sock, aname in outputs.items():
            aov = tree.nodes.new("ShaderNodeOutputAOV")
            aov.aov_name = aname
            kind = "Value" if dict(AOVS)[aname] == "VALUE" else "Color"
            tree.links.new(_sock(tex.outputs, sock), aov.inputs[kind])
        me.materials.append(mat)
        nodes_out.append(tex)
    s = sc.render.image_settings
    s.media_type = "MULTI_LAYER_IMAGE"
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "32"
    s.exr_codec = "ZIP"
    path = tmp_path / f"{name}.exr"
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    ch = _read_multilayer(path)
    results = []
    for idx, tex in enumerate(nodes_out):
        r0, c0 = PIX * (idx // COLS), PIX * (idx % COLS)
        sl = (slice(r0, r0 + PIX), slice(c0, c0 + PIX))
        res = {}
        for aname, atype in AOVS:
            if atype == "VALUE":
                key = f"ViewLayer.{aname}.X"
                if key in ch:
                    res[aname] = ch[key][sl]
            else:
                res[aname] = np.stack([ch[f"ViewLayer.{aname}.{c}"][sl] for c in "RGB"], -1)
        params = {s.name: (tuple(s.default_value) if hasattr(s.default_value, "__len__") else float(s.default_value))
                  for s in tex.inputs if s.name != "Vector"}
        props = {k: getattr(tex, k) for k in cases[idx][1]}      # read back: float32 values
        results.append((res, params, props))
    return results


def _eval(fn, args_of_pixel):
    """(PIX, PIX, k) array of fn(*args_of_pixel(X, Y, Z, W)) over the plane's pixel centres."""
    X, Y, Z, W = _pixel_coords()
    out = [[fn(*args_of_pixel(X[i, j], Y[i, j], Z[i, j], W[i, j])) for j in range(PIX)] for i in range(PIX)]
    return np.asarray(out, np.float64)


# ----------------------------------------------------------------------------
# Cases: (bl_idname, node properties, node inputs, {output socket: AOV}) and the evaluator
# ----------------------------------------------------------------------------
def _noise_case(dims="3D", ntype="FBM", normalize=True, **inp):
    base = {"Scale": 5.0, "Detail": 2.0, "Roughness": 0.5, "Lacunarity": 2.0, "Distortion": 0.0,
            "Offset": 0.0, "Gain": 1.0}
    base.update(inp)
    return ("ShaderNodeTexNoise", {"noise_dimensions": dims, "noise_type": ntype, "normalize": normalize},
            base, {"Factor": "v0", "Color": "c0"})


NOISE_CASES = [
    _noise_case(),
    _noise_case(Detail=3.7, Roughness=0.6, Lacunarity=2.3, Distortion=0.8),
    _noise_case(normalize=False, Detail=0.0, Scale=3.0),
    _noise_case(normalize=False, Detail=4.25, Roughness=0.7, Scale=2.0, Distortion=-1.5),
    _noise_case(ntype="MULTIFRACTAL", Detail=2.5, Roughness=0.6),
    _noise_case(ntype="RIDGED_MULTIFRACTAL", Detail=3.0, Offset=1.0, Gain=1.5),
    _noise_case(ntype="HYBRID_MULTIFRACTAL", Detail=3.3, Offset=0.5, Gain=1.2),
    _noise_case(ntype="HETERO_TERRAIN", Detail=2.4, Offset=0.75, Distortion=0.4),
    _noise_case(dims="1D", Detail=3.5, Distortion=0.6),
    _noise_case(dims="2D", Detail=2.5, Distortion=0.5),
    _noise_case(dims="4D", Detail=1.5, Distortion=0.3),
    _noise_case(dims="4D", ntype="RIDGED_MULTIFRACTAL", Detail=2.0, Offset=1.0, Gain=2.0),
    _noise_case(dims="2D", ntype="HETERO_TERRAIN", Detail=3.0, Offset=0.5),
    _noise_case(dims="1D", ntype="MULTIFRACTAL", Detail=2.0),
    _noise_case(dims="2D", ntype="HYBRID_MULTIFRACTAL", Detail=2.7, Offset=0.3, Gain=1.0, Distortion=0.2),
    _noise_case(dims="4D", ntype="MULTIFRACTAL", normalize=False, Detail=1.25, Roughness=0.4),
    _noise_case(Detail=5.5, Roughness=0.55, Lacunarity=2.7, Scale=2.5),
    _noise_case(ntype="RIDGED_MULTIFRACTAL", Detail=2.6, Offset=0.9, Gain=3.0, Lacunarity=1.9),
    _noise_case(ntype="HYBRID_MULTIFRACTAL", Detail=6.5, Offset=0.2, Gain=4.0, Roughness=0.8),
    _noise_case(dims="1D", ntype="HETERO_TERRAIN", Detail=2.2, Offset=1.0, Distortion=0.3),
]


def _noise_eval(props, prm):
    dims = P.DIMENSIONS[props["noise_dimensions"]]
    nt = P.NOISE_TYPES[props["noise_type"]]
    return lambda X, Y, Z, W: (X, Y, Z, W, dims, prm["Scale"], prm["Detail"], prm["Roughness"], prm["Lacunarity"],
                               prm["Distortion"], props["normalize"], nt, prm["Offset"], prm["Gain"])


def _vor_case(dims="3D", feature="F1", metric="EUCLIDEAN", normalize=False, **inp):
    base = {"Scale": 5.0, "Detail": 0.0, "Roughness": 0.5, "Lacunarity": 2.0, "Smoothness": 1.0,
            "Exponent": 0.5, "Randomness": 1.0}
    base.update(inp)
    if feature == "N_SPHERE_RADIUS":
        outs = {"Radius": "v0"}
    elif feature == "DISTANCE_TO_EDGE":
        outs = {"Distance": "v0"}
    else:
        outs = {"Distance": "v0", "Color": "c0", "Position": "c1", "W": "v1"}
    return ("ShaderNodeTexVoronoi", {"voronoi_dimensions": dims, "feature": feature, "distance": metric,
                                     "normalize": normalize}, base, outs)


VORONOI_CASES = [
    _vor_case(),
    _vor_case(feature="F2", metric="MANHATTAN"),
    _vor_case(feature="SMOOTH_F1", metric="CHEBYCHEV", Smoothness=0.8),
    _vor_case(metric="MINKOWSKI", Exponent=1.5, Randomness=0.7),
    _vor_case(feature="DISTANCE_TO_EDGE"),
    _vor_case(feature="N_SPHERE_RADIUS", Randomness=0.8),
    _vor_case(Detail=2.5, Roughness=0.6, Lacunarity=2.1, normalize=True),
    _vor_case(feature="F2", Detail=1.5, normalize=True, Randomness=0.6),
    _vor_case(feature="SMOOTH_F1", Detail=1.0, Smoothness=0.5, normalize=True),
    _vor_case(feature="DISTANCE_TO_EDGE", Detail=1.5, normalize=True, Randomness=0.9),
    _vor_case(metric="MINKOWSKI", Exponent=3.0, feature="F2", Scale=3.0),
    _vor_case(dims="1D", feature="F1", Detail=1.5, normalize=True),
    _vor_case(dims="1D", feature="SMOOTH_F1", Smoothness=0.6),
    _vor_case(dims="1D", feature="DISTANCE_TO_EDGE"),
    _vor_case(dims="1D", feature="N_SPHERE_RADIUS"),
    _vor_case(dims="2D", feature="F1", metric="MANHATTAN"),
    _vor_case(dims="2D", feature="F2", Detail=1.0, normalize=True),
    _vor_case(dims="2D", feature="SMOOTH_F1", Smoothness=1.0),
    _vor_case(dims="2D", feature="DISTANCE_TO_EDGE", Detail=1.0),
    _vor_case(dims="2D", feature="N_SPHERE_RADIUS"),
    _vor_case(dims="4D", feature="F1", Scale=3.0),
    _vor_case(dims="4D", feature="F2", metric="CHEBYCHEV", Scale=3.0),
    _vor_case(dims="4D", feature="SMOOTH_F1", Smoothness=0.4, Scale=2.0),
    _vor_case(dims="4D", feature="DISTANCE_TO_EDGE", Scale=3.0),
    _vor_case(dims="4D", feature="N_SPHERE_RADIUS", Scale=3.0, Randomness=0.9),
    _vor_case(dims="4D", metric="MINKOWSKI", Exponent=0.8, Scale=2.0, Detail=1.0, normalize=True),
    _vor_case(dims="1D", feature="F2", Detail=2.0, Roughness=0.7, normalize=True),
    _vor_case(dims="2D", metric="CHEBYCHEV", Detail=1.7, Lacunarity=2.5, normalize=True),
    _vor_case(dims="2D", feature="F2", metric="MINKOWSKI", Exponent=0.5, Randomness=0.5),
    _vor_case(feature="SMOOTH_F1", Smoothness=0.0, Randomness=0.3),
]


def _vor_eval(props, prm):
    dims = P.DIMENSIONS[props["voronoi_dimensions"]]
    ft, mt = P.VORONOI_FEATURES[props["feature"]], P.VORONOI_METRICS[props["distance"]]
    return lambda X, Y, Z, W: (X, Y, Z, W, dims, prm["Scale"], prm["Detail"], prm["Roughness"], prm["Lacunarity"],
                               prm["Smoothness"], prm["Exponent"], prm["Randomness"], ft, mt, props["normalize"])


def _wave_case(wtype="BANDS", bands="X", rings="X", profile="SIN", **inp):
    base = {"Scale": 5.0, "Distortion": 0.0, "Detail": 2.0, "Detail Scale": 1.0, "Detail Roughness": 0.5,
            "Phase Offset": 0.0}
    base.update(inp)
    return ("ShaderNodeTexWave", {"wave_type": wtype, "bands_direction": bands, "rings_direction": rings,
                                  "wave_profile": profile}, base, {"Factor": "v0", "Color": "c0"})


WAVE_CASES = [
    _wave_case(),
    _wave_case(bands="Y", profile="SAW", Scale=2.0),
    _wave_case(bands="Z", profile="TRI"),
    _wave_case(bands="DIAGONAL", Distortion=2.0, Detail=2.0, **{"Phase Offset": 0.5}),
    _wave_case(wtype="RINGS", rings="X"),
    _wave_case(wtype="RINGS", rings="Y", profile="TRI", Scale=3.0),
    _wave_case(wtype="RINGS", rings="Z", profile="SAW", Distortion=1.5, Detail=3.5,
               **{"Detail Scale": 2.0, "Detail Roughness": 0.7}),
    _wave_case(wtype="RINGS", rings="SPHERICAL", Distortion=5.0, Detail=1.0, **{"Phase Offset": 1.25}),
    _wave_case(bands="X", profile="SAW", Distortion=3.0, Detail=4.5, **{"Detail Scale": 3.0}),
    _wave_case(bands="DIAGONAL", profile="TRI", Scale=2.0, **{"Phase Offset": -2.0}),
]


def _wave_eval(props, prm):
    codes = (P.WAVE_TYPES[props["wave_type"]], P.WAVE_BANDS_DIRECTIONS[props["bands_direction"]],
             P.WAVE_RINGS_DIRECTIONS[props["rings_direction"]], P.WAVE_PROFILES[props["wave_profile"]])
    return lambda X, Y, Z, W: (X, Y, Z) + codes + (prm["Scale"], prm["Distortion"], prm["Detail"],
                                                   prm["Detail Scale"], prm["Detail Roughness"], prm["Phase Offset"])


C1, C2, CM = (0.8, 0.1, 0.2, 1.0), (0.1, 0.7, 0.3, 1.0), (0.05, 0.05, 0.9, 1.0)


def _brick_case(offset=0.5, offset_frequency=2, squash=1.0, squash_frequency=2, **inp):
    base = {"Color1": C1, "Color2": C2, "Mortar": CM, "Scale": 5.0, "Mortar Size": 0.02, "Mortar Smooth": 0.1,
            "Bias": 0.0, "Brick Width": 0.5, "Row Height": 0.25}
    base.update({k.replace("_", " "): v for k, v in inp.items()})
    return ("ShaderNodeTexBrick", {"offset": offset, "offset_frequency": offset_frequency, "squash": squash,
                                   "squash_frequency": squash_frequency}, base, {"Factor": "v0", "Color": "c0"})


BRICK_CASES = [
    _brick_case(),
    _brick_case(offset=0.3, offset_frequency=1, squash=0.6, squash_frequency=3, Bias=-0.3, Mortar_Size=0.05,
                Mortar_Smooth=0.0, Scale=3.0),
    _brick_case(Mortar_Size=0.08, Mortar_Smooth=0.7, Bias=0.4, Brick_Width=0.7, Row_Height=0.3, Scale=4.0),
    _brick_case(offset=0.75, offset_frequency=3, squash=1.5, squash_frequency=1, Scale=6.0, Mortar_Size=0.04,
                Mortar_Smooth=0.3),
]


def _brick_eval(props, prm):
    return lambda X, Y, Z, W: (X, Y, Z, prm["Scale"], prm["Mortar Size"], prm["Mortar Smooth"], prm["Bias"],
                               prm["Brick Width"], prm["Row Height"], props["offset"], props["offset_frequency"],
                               props["squash"], props["squash_frequency"])


def _magic_case(depth=2, **inp):
    base = {"Scale": 5.0, "Distortion": 1.0}
    base.update(inp)
    return ("ShaderNodeTexMagic", {"turbulence_depth": depth}, base, {"Factor": "v0", "Color": "c0"})


MAGIC_CASES = [_magic_case(), _magic_case(depth=0, Distortion=0.0), _magic_case(depth=5, Distortion=2.5),
               _magic_case(depth=10, Distortion=0.7, Scale=3.0), _magic_case(depth=7, Distortion=1.3, Scale=1.5)]


def _magic_eval(props, prm):
    return lambda X, Y, Z, W: (X, Y, Z, props["turbulence_depth"], prm["Scale"], prm["Distortion"])


WHITE_CASES = [("ShaderNodeTexWhiteNoise", {"noise_dimensions": d}, {}, {"Value": "v0", "Color": "c0"})
               for d in ("1D", "2D", "3D", "4D")]


def _white_eval(props, prm):
    dims = P.DIMENSIONS[props["noise_dimensions"]]
    return lambda X, Y, Z, W: (X, Y, Z, W, dims)


GROUPS = {
    "noise": (NOISE_CASES, _noise_eval, P.noise_texture),
    "voronoi": (VORONOI_CASES, _vor_eval, P.voronoi_texture),
    "wave": (WAVE_CASES, _wave_eval, P.wave_texture),
    "brick": (BRICK_CASES, _brick_eval, P.brick_texture),
    "magic": (MAGIC_CASES, _magic_eval, P.magic_texture),
    "white_noise": (WHITE_CASES, _white_eval, P.white_noise_texture),
}


def _expected(group, props, prm, vals):
    """AOV name -> expected array from the function's (PIX, PIX, k) outputs ``vals``."""
    if group == "brick":
        fac, tint = vals[..., 0], vals[..., 1]
        col = np.array([[P.brick_color(fac[i, j], tint[i, j], *prm["Color1"][:3], *prm["Color2"][:3],
                                       *prm["Mortar"][:3]) for j in range(PIX)] for i in range(PIX)])
        return {"v0": fac, "c0": col}
    if group == "voronoi":
        if props["feature"] == "N_SPHERE_RADIUS":
            return {"v0": vals[..., 8]}
        if props["feature"] == "DISTANCE_TO_EDGE":
            return {"v0": vals[..., 0]}
        return {"v0": vals[..., 0], "c0": vals[..., 1:4], "c1": vals[..., 4:7], "v1": vals[..., 7]}
    return {"v0": vals[..., 0], "c0": vals[..., 1:4]}


def _tolerance(group, aov, prm):
    """Max |STPM - Cycles| allowed (measured maxima in brackets; Cycles is float32, STPM float64).

    * white noise: exact (hashes of the same float32 bits)                                 [0]
    * voronoi, brick: float32 rounding of distances / mixes                                 [6e-7, 2e-6]
    * noise factor, and colour without distortion                                          [2e-6, 5e-7]
    * noise colour with distortion: the colour channels add offsets in [100, 200] to the
      distorted point, where a float32 ulp is 1.5e-5; the displacement itself (a noise
      value times Distortion) is rounded differently in float32 and float64, so the
      offset points can differ by an ulp, times the noise gradient                         [1.1e-4]
    * wave, magic: sin / cos of float32 arguments of up to ~100 (an ulp ~ 1e-5)              [1.1e-5, 1e-5]
    """
    if group == "white_noise":
        return 0.0
    if group == "noise":
        return 3e-4 if (aov == "c0" and prm["Distortion"] != 0.0) else 1e-5
    if group in ("wave", "magic"):
        return 5e-5
    return 1e-5


@pytest.mark.parametrize("group", list(GROUPS))
def test_procedural_texture_matches_cycles(group, tmp_path):
    pytest.importorskip("bpy")
    pytest.importorskip("OpenImageIO")
    cases, make_args, fn = GROUPS[group]
    rendered = render_cases(cases, tmp_path, group)
    failures = []
    for case, (cyc, prm, props) in zip(cases, rendered):
        vals = _eval(fn, make_args(props, prm))
        expected = _expected(group, props, prm, vals)
        # every case must exercise something: some output varies over the plane
        assert max(float(np.ptp(cyc[aov])) for aov in expected) > 0.05, (props, case[2])
        for aov, exp in expected.items():
            got = cyc[aov]
            err = np.abs(got - exp)
            if err.ndim == 3:
                err = err.max(-1)
            tol = _tolerance(group, aov, prm)
            assert np.isfinite(got).all()
            if not err.max() <= tol:
                failures.append(f"{props} {case[2]} {aov}: max err {err.max():.3g} > {tol:g} "
                                f"({int((err > tol).sum())} px)")
    assert not failures, "\n".join(failures)

