"""Fixes from the third artist review (an evening living room, review/make_interior.py), through the
real bpy module: anisotropy the kernels do not render is named in the render report.
"""
from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_light, add_mesh, export_now, fresh, node_material  # noqa: E402

import addon  # noqa: E402

addon.register()


def _lamp(kind: str, textured: bool):
    """A sphere whose material is a Principled BSDF (Anisotropic 0.8) or a Glossy BSDF (Anisotropy
    0.8), with a constant colour or an image-free texture on it (then the node graph renders it)."""
    fresh()
    add_camera()
    add_light("POINT", energy=500.0, location=(1, -1, 3))
    mat, node = node_material("Brushed", kind)
    node.inputs["Anisotropic" if kind == "ShaderNodeBsdfPrincipled" else "Anisotropy"].default_value = 0.8
    if textured:
        checker = mat.node_tree.nodes.new("ShaderNodeTexChecker")
        mat.node_tree.links.new(checker.outputs["Color"], node.inputs["Base Color" if kind == "ShaderNodeBsdfPrincipled"
                                                                        else "Color"])
    add_mesh("sphere", "Lamp", material=mat)


@pytest.mark.parametrize("textured", [False, True])
@pytest.mark.parametrize("kind", ["ShaderNodeBsdfPrincipled", "ShaderNodeBsdfGlossy"])
def test_anisotropy_is_named_in_the_report(kind, textured):
    # The review's brushed-metal floor lamp (Principled Anisotropic 0.8) rendered isotropic without a word
    _lamp(kind, textured)
    _scene, warnings = export_now()
    hits = [w for w in warnings if "Anisotrop" in w and "not rendered" in w]
    assert len(hits) == 1, warnings
    assert "'Brushed'" in hits[0] or "Brushed" in hits[0]


def test_zero_anisotropy_is_not_warned():
    _lamp("ShaderNodeBsdfPrincipled", False)
    bpy.data.materials["Brushed"].node_tree.nodes["Principled BSDF"].inputs["Anisotropic"].default_value = 0.0
    _scene, warnings = export_now()
    assert not [w for w in warnings if "Anisotrop" in w], warnings


def test_cycles_denoising_data_switch_is_named_when_its_passes_are_missing():
    # A view layer with Cycles' Denoising Data ticked (the review's file, made as a Cycles user
    # makes it) got no Denoising passes from STPM and no word about it
    from addon.engine import unsupported_passes
    fresh()
    vl = bpy.context.scene.view_layers[0]
    assert not any("Denoising" in n for n in unsupported_passes(vl))
    vl.cycles.denoising_store_passes = True
    missing = unsupported_passes(vl)
    assert len(missing) == 1 and missing[0].startswith("Denoising Data") and "Sampling > Denoising" in missing[0]
    # with STPM's Denoise on, Albedo and Normal are written: only Cycles' Denoising Depth is missing
    assert unsupported_passes(vl, denoise=True) == ["Denoising Depth"]


@pytest.mark.parametrize("textured", [False, True])
@pytest.mark.parametrize("name, value", [("Diffuse Roughness", 0.5), ("Thin Film Thickness", 300.0),
                                         ("Specular Tint", (1.0, 0.5, 0.2, 1.0))])
def test_other_ignored_principled_inputs_are_named(name, value, textured):
    # The review found these Principled inputs ignored without a word (the kernels have no
    # Oren-Nayar base, no thin film, an untinted specular layer)
    _lamp("ShaderNodeBsdfPrincipled", textured)
    node = bpy.data.materials["Brushed"].node_tree.nodes["Principled BSDF"]
    node.inputs["Anisotropic"].default_value = 0.0
    sock = node.inputs.get(name)
    if sock is None:
        pytest.skip(f"this Blender's Principled BSDF has no {name} input")
    sock.default_value = value
    _scene, warnings = export_now()
    hits = [w for w in warnings if name in w]
    assert len(hits) == 1, warnings
    sock.default_value = 0.0 if isinstance(value, float) else (1.0, 1.0, 1.0, 1.0)
    _scene, warnings = export_now()
    assert not [w for w in warnings if name in w], warnings
