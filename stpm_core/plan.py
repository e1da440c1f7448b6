"""The effects plan: which effects a scene calls for, and why (``stpm plan``).

``make_plan(scene, settings) -> dict`` with bool keys ``motion_blur``,
``caustics``, ``indirect``, ``time_dependent`` and ``reasons`` (list of str).

The renderer computes the plan it acts on in
:func:`stpm_core.render.plan_effects`; this module is the stable entry point
for the CLI and the add-on and delegates to it, so what ``stpm plan`` prints is
what ``stpm render`` does.  The fallback below (used only if the renderer
cannot be imported) is the minimal rule set:

* motion_blur = the scene has motion inside an open shutter;
* caustics = some material has a metallic / transmission / specular lobe and
  there is a light;
* indirect = some material reflects diffusely and there is a light;
* time_dependent = motion_blur.
"""
from __future__ import annotations

__all__ = ["make_plan", "format_plan"]

_KEYS = ("motion_blur", "caustics", "indirect", "time_dependent")


def _minimal_plan(scene) -> dict:
    """Plan from the scene alone (no renderer needed)."""
    has_light = bool(scene.lights)
    motion = bool(scene.has_motion)
    specular = [m.name for m in scene.materials if m.metallic > 0 or m.transmission > 0 or m.specular > 0]
    diffuse = [m.name for m in scene.materials if m.diffuse_weight > 0]
    caustics = bool(specular) and has_light
    indirect = bool(diffuse) and has_light
    reasons = [
        "motion_blur: " + ("something moves while the shutter is open" if motion else "off (nothing moves in the shutter)"),
        "caustics: " + (f"specular materials {specular[:3]} and a light" if caustics
                        else "off (" + ("no light" if specular else "no specular material") + ")"),
        "indirect: " + (f"diffuse materials {diffuse[:3]} and a light" if indirect
                        else "off (" + ("no light" if diffuse else "no diffuse material") + ")"),
        "time_dependent: " + ("photons carry time (the scene moves)" if motion else "off"),
    ]
    return {"motion_blur": motion, "caustics": caustics, "indirect": indirect,
            "time_dependent": motion, "reasons": reasons}


def make_plan(scene, settings=None) -> dict:
    """The effects plan for ``scene`` (see module docstring)."""
    try:
        from .render import plan_effects
    except ImportError:
        return _minimal_plan(scene)
    return plan_effects(scene, settings)


def format_plan(plan: dict) -> str:
    """Human-readable plan: one ``effect: yes/no`` line each, then the reasons."""
    lines = [f"{k:15s} {'yes' if plan.get(k) else 'no'}" for k in _KEYS]
    lines += ["", "why:"] + [f"  - {r}" for r in plan.get("reasons", [])]
    extra = {k: v for k, v in plan.items() if k not in _KEYS and k != "reasons"}
    lines += [f"{k}: {v}" for k, v in extra.items()]
    return "\n".join(lines)
