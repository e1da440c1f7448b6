"""Opcodes of the shader-node program and their operand layouts (shared by the compiler
:mod:`stpm_core.nodes.compile` and the interpreter :mod:`stpm_core.kernels.svm`).

A material's program is a run of float64 words in the scene's program array, starting at the
material's ``C_PROGRAM`` column::

    [n_slots, n_const, closure_at, const_0 .. const_{n_const-1}, value code..., closure code...]

Slots are the interpreter's per-hit registers (float64): the constants fill slots
0 .. n_const - 1, node outputs the slots after them; a colour or vector takes three consecutive
slots.  An instruction is its opcode followed by the operands listed in :data:`LAYOUT` (slot
indices unless named otherwise; -1 = output not used).  The value code (every instruction but the
closure ones) runs for a batch of hits at once, instruction by instruction; the closure code,
from word ``closure_at`` (relative to the program's first word) on, is walked per hit: a closure
instruction (``BSDF_*``, ``EMISSION``, ``TRANSPARENT``) ends it, ``MIX_SHADER`` picks one of its two
branches with probability Fac (an unbiased estimate of Blender's linear blend of the two closures),
``ADD_SHADER`` one of its two with probability 1/2 and doubles the closure's weight (an unbiased
estimate of their sum for emission, transparency and diffuse colour).
"""
from __future__ import annotations

__all__ = ["OP", "LAYOUT", "MATH_OPS", "VMATH_OPS", "BLEND_MODES", "MAPPING_TYPES", "INTERPOLATIONS",
           "EXTENSIONS", "GRADIENT_TYPES", "RAMP_INTERPOLATIONS", "CONVERT", "MAP_RANGE_TYPES", "COLOR_MODES", "NORMAL_MAP_SPACES"]

# Operand names; "*" marks a vec3 slot (three slots), "#" an integer property.
LAYOUT = {
    "END": (),
    "CONVERT": ("#kind", "in", "out", "*luma"),         # CONVERT kinds below; luma: COLOR_TO_FLOAT's weights
    # offset: 0 at the hit; 1 / 2 at the hit moved along the surface's x / y differential (Bump)
    "TEXCOORD": ("#offset", "*generated", "*normal", "*uv", "*object", "*reflection"),
    "UVMAP": ("#layer", "#offset", "*out"),
    "GEOMETRY": ("#offset", "*position", "*normal", "*true_normal", "*incoming", "backfacing"),
    "MAPPING": ("#type", "*vector", "*location", "*rotation", "*scale", "*out"),
    "MATH": ("#op", "a", "b", "c", "#clamp", "out"),
    "VECTOR_MATH": ("#op", "*a", "*b", "*c", "scale", "*out", "value"),
    "MIX_FLOAT": ("fac", "a", "b", "#clamp_fac", "out"),
    "MIX_VECTOR": ("fac", "*a", "*b", "#clamp_fac", "*out"),
    "MIX_COLOR": ("#blend", "fac", "*a", "*b", "#clamp_fac", "#clamp_result", "*out"),
    "INVERT": ("fac", "*color", "*out"),
    "HSV": ("hue", "sat", "val", "fac", "*color", "*out"),
    "BRIGHT_CONTRAST": ("*color", "bright", "contrast", "*out"),
    "GAMMA": ("*color", "gamma", "*out"),
    "SEPARATE_COLOR": ("#mode", "*color", "r", "g", "b"),
    "COMBINE_COLOR": ("#mode", "r", "g", "b", "*out"),
    "SEPARATE_XYZ": ("*vector", "x", "y", "z"),
    "COMBINE_XYZ": ("x", "y", "z", "*out"),
    "CLAMP": ("#type", "value", "min", "max", "out"),
    "MAP_RANGE": ("#type", "value", "from_min", "from_max", "to_min", "to_max", "steps", "#clamp", "out"),
    "RAMP": ("fac", "#interp", "#n", "*color", "alpha"),          # then the n x (r, g, b, a) table on [0, 1]
    "CURVES": ("fac", "*color", "#n", "*out"),                      # then 3 x n table words (R, G, B on [0, 1])
    # then the UDIM tile table: #tiles x (tile number, texture id); #image unused when #tiles > 0
    "TEX_IMAGE": ("#image", "#interp", "#ext", "#unassociate", "*vector", "*color", "alpha", "#tiles"),
    "TEX_CHECKER": ("*vector", "*color1", "*color2", "scale", "*color", "fac"),
    "TEX_GRADIENT": ("#type", "*vector", "*color", "fac"),
    "TEX_NOISE": ("#dims", "#type", "#normalize", "#color_used", "*vector", "w", "scale", "detail", "roughness",
                  "lacunarity", "offset", "gain", "distortion", "fac", "*color"),
    "TEX_VORONOI": ("#dims", "#feature", "#metric", "#normalize", "*vector", "w", "scale", "detail", "roughness",
                    "lacunarity", "smoothness", "exponent", "randomness", "distance", "*color", "*position", "w_out",
                    "radius"),
    "TEX_WAVE": ("#type", "#bands_direction", "#rings_direction", "#profile", "*vector", "scale", "distortion",
                 "detail", "detail_scale", "detail_roughness", "phase", "*color", "fac"),
    "TEX_BRICK": ("#offset", "#offset_frequency", "#squash", "#squash_frequency", "*vector", "*color1", "*color2",
                  "*mortar", "scale", "mortar_size", "mortar_smooth", "bias", "brick_width", "row_height",
                  "*color", "fac"),
    "TEX_MAGIC": ("#depth", "*vector", "scale", "distortion", "*color", "fac"),
    "TEX_WHITE_NOISE": ("#dims", "*vector", "w", "value", "*color"),
    "NORMAL_MAP": ("#space", "#layer", "*color", "strength", "*out"),    # space: NORMAL_MAP_SPACES
    "BUMP": ("#invert", "strength", "distance", "hc", "hx", "hy", "*normal", "*out"),   # normal -1: the surface's
    "BSDF_PRINCIPLED": ("*base", "metallic", "roughness", "ior", "alpha", "transmission", "specular",
                        "*emission", "strength", "*normal",                  # normal: -1 = the surface's
                        "coat_weight", "coat_roughness", "coat_ior", "*coat_tint",    # the coat layer
                        "*coat_normal"),                                     # -1: the BSDF's normal
    "BSDF_DIFFUSE": ("*color", "*normal"),
    "BSDF_GLOSSY": ("*color", "roughness", "*normal"),
    "BSDF_GLASS": ("*color", "roughness", "ior", "*normal"),
    "EMISSION": ("*color", "strength"),
    "MIX_SHADER": ("fac", "#jump"),                                  # jump: word index of the second branch
    "TRANSPARENT": ("*color",),                                      # the ray passes, tinted by color
    "ADD_SHADER": ("#jump",),                                        # one branch, each with 1/2, weight 2
    # a colour attribute (or a UV map read by name: (u, v, 0), alpha 1) per corner; fac = average
    "ATTRIBUTE": ("#layer", "#offset", "*color", "fac", "alpha"),
}
OP = {name: i for i, name in enumerate(LAYOUT)}

CONVERT = {"COLOR_TO_FLOAT": 0, "VECTOR_TO_FLOAT": 1, "FLOAT_TO_VEC": 2}

# Blender enum names -> codes
MATH_OPS = {n: i for i, n in enumerate((
    "ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM", "SQRT", "INVERSE_SQRT",
    "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM", "LESS_THAN", "GREATER_THAN", "SIGN", "COMPARE",
    "SMOOTH_MIN", "SMOOTH_MAX", "ROUND", "FLOOR", "CEIL", "TRUNC", "FRACT", "MODULO", "FLOORED_MODULO",
    "WRAP", "SNAP", "PINGPONG", "SINE", "COSINE", "TANGENT", "ARCSINE", "ARCCOSINE", "ARCTANGENT",
    "ARCTAN2", "SINH", "COSH", "TANH", "RADIANS", "DEGREES"))}
VMATH_OPS = {n: i for i, n in enumerate((
    "ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "CROSS_PRODUCT", "PROJECT", "REFLECT",
    "REFRACT", "FACEFORWARD", "DOT_PRODUCT", "DISTANCE", "LENGTH", "SCALE", "NORMALIZE", "ABSOLUTE",
    "POWER", "SIGN", "MINIMUM", "MAXIMUM", "FLOOR", "CEIL", "FRACTION", "MODULO", "WRAP", "SNAP", "SINE",
    "COSINE", "TANGENT"))}
BLEND_MODES = {n: i for i, n in enumerate((
    "MIX", "DARKEN", "MULTIPLY", "BURN", "LIGHTEN", "SCREEN", "DODGE", "ADD", "OVERLAY", "SOFT_LIGHT",
    "LINEAR_LIGHT", "DIFFERENCE", "EXCLUSION", "SUBTRACT", "DIVIDE", "HUE", "SATURATION", "COLOR", "VALUE"))}
MAPPING_TYPES = {"POINT": 0, "TEXTURE": 1, "VECTOR": 2, "NORMAL": 3}
INTERPOLATIONS = {"Closest": 0, "Linear": 1, "Cubic": 2, "Smart": 2}
EXTENSIONS = {"REPEAT": 0, "EXTEND": 1, "CLIP": 2, "MIRROR": 3}
GRADIENT_TYPES = {n: i for i, n in enumerate(("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL",
                                              "QUADRATIC_SPHERE", "RADIAL"))}
RAMP_INTERPOLATIONS = {"CONSTANT": 0, "LINEAR": 1, "EASE": 2, "CARDINAL": 1, "B_SPLINE": 1}
MAP_RANGE_TYPES = {"LINEAR": 0, "STEPPED": 1, "SMOOTHSTEP": 2, "SMOOTHERSTEP": 3}
COLOR_MODES = {"RGB": 0, "HSV": 1, "HSL": 2}
NORMAL_MAP_SPACES = {"TANGENT": 0, "OBJECT": 1, "WORLD": 2, "BLENDER_OBJECT": 3, "BLENDER_WORLD": 4}
