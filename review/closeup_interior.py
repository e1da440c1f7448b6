"""A close-up of review/out/interior.blend (the same file, lens and aim changed in memory), both renderers.

python review/closeup_interior.py TARGET SPP  (TARGET: glass | curtain | lamp)
Writes review/out/close_<target>_{cycles,stpm}<TAG>.exr; prints times.  STPM: the PRESET (Preview) with SPP
samples, max_depth DEPTH if set; ENGINES=CYCLES,STPM by default."""
import os, sys, time
from pathlib import Path
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import bpy, addon
from mathutils import Vector
addon.register()
target, spp = sys.argv[1], int(sys.argv[2])
AIM = {"glass": ((0.18, 0.3, 0.58), 260, 0.4), "curtain": ((-0.75, 2.4, 1.45), 90, 1.0),
       "lamp": ((1.8, 1.2, 1.5), 120, 0.8)}
for engine in os.environ.get("ENGINES", "CYCLES,STPM").split(","):
    bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "interior.blend"))
    s = bpy.context.scene; s.frame_set(12)
    cam = s.camera; aim, lens, _ = AIM[target]
    cam.animation_data_clear(); cam.location = (0.0, -2.35, 1.6)
    cam.rotation_euler = (Vector(aim) - cam.location).to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = lens
    if target != "glass":
        cam.data.dof.use_dof = False
    s.render.resolution_x = s.render.resolution_y = 200
    s.render.image_settings.media_type = "IMAGE"; s.render.image_settings.file_format = "OPEN_EXR"
    s.render.image_settings.color_depth = "32"; s.render.use_file_extension = False
    s.render.engine = engine
    if engine == "CYCLES":
        cy = s.cycles; cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", spp, False, False
        cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    else:
        bpy.ops.stpm.apply_preset(preset=os.environ.get("PRESET", "PREVIEW")); s.stpm.samples = spp
        if os.environ.get("DEPTH"):
            s.stpm.max_depth = int(os.environ["DEPTH"])
    s.render.filepath = str(HERE / "out" / f"close_{target}_{engine.lower()}{os.environ.get('TAG', '')}.exr")
    t = time.time(); bpy.ops.render.render(write_still=True); print(engine, f"{time.time() - t:.1f} s")
