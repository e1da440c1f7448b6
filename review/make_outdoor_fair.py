"""review/out/outdoor.blend without what STPM does not render (warned): the CarKey light's linking
cleared, the Holdout box, the Shadow Catcher card and the fog cube hidden from renders.  Writes
review/out/outdoor_fair.blend, on which STPM and Cycles render the same scene.
python review/make_outdoor_fair.py   (PYTHONPATH = checkout)"""
import sys
from pathlib import Path
import bpy
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import addon  # noqa: E402
addon.register()
bpy.ops.wm.open_mainfile(filepath=str(HERE / "out" / "outdoor.blend"))
bpy.data.objects["CarKey"].light_linking.receiver_collection = None
for name in ("HoldoutBox", "CatcherCard", "FogCube"):
    bpy.data.objects[name].hide_render = True
bpy.ops.wm.save_as_mainfile(filepath=str(HERE / "out" / "outdoor_fair.blend"))
