""""Bake Unsupported Inputs" (``bpy.ops.stpm.bake_inputs``): bake, for the current frame, every
shader input the node interpreter cannot evaluate that has no cached bake yet.

One child process on a copy of the file does the Cycles bakes (:mod:`.export.bake`); F12 then
reads them from the cache.  The operator blocks Blender while the child runs (a few seconds per
input at 512 x 512) and reports what it baked and what cannot be baked.
"""
from __future__ import annotations

import bpy


class STPM_OT_bake_inputs(bpy.types.Operator):
    """Bake, with Cycles, the shader inputs STPM's node interpreter cannot evaluate (a Gabor texture,
    an attribute, ...), so F12 renders them instead of their default values"""

    bl_idname = "stpm.bake_inputs"
    bl_label = "Bake Unsupported Inputs"
    bl_options = {"REGISTER"}

    def execute(self, context):
        from . import _core
        from .batch import bake_current
        scene = context.scene
        lines = []
        try:
            report = bake_current(scene, log=lines.append)
        except (_core.StpmError, RuntimeError, OSError) as exc:
            self.report({"ERROR"}, f"STPM bake: {exc}")
            return {"CANCELLED"}
        counts = report.get("statuses", {})
        for key, why in report.get("failed", {}).items():
            self.report({"WARNING"}, f"STPM bake {key}: {why}")
        summary = (f"STPM bake: {len(report.get('baked', []))} baked now in {report.get('seconds', 0.0):.1f} s; "
                   f"{counts.get('baked', 0)} input(s) baked, {counts.get('blocked', 0)} cannot be baked, "
                   f"{counts.get('failed', 0)} failed (see the render report for why)")
        self.report({"WARNING"} if counts.get("failed") else {"INFO"}, summary)
        return {"FINISHED"}


classes = (STPM_OT_bake_inputs,)
register, unregister = bpy.utils.register_classes_factory(classes)
