"""Export a .blend frame and dump the scene file's header + per-array digests (to find what differs run to run)."""
import sys, json, hashlib
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import numpy as np
from addon.batch import load_blend
from stpm_core.scenefile import scene_to_arrays
from stpm_core.partial import scene_hash
scene, _ = load_blend(sys.argv[1], frame=int(sys.argv[2]), bake=True)
header, arrays = scene_to_arrays(scene)
d = {"header": json.loads(json.dumps(header, sort_keys=True, default=str)),
     "arrays": {k: hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()[:16] + f" {v.dtype} {v.shape}" for k, v in arrays.items()},
     "hash": scene_hash(scene)}
if "meshes/4/uv/0" in arrays: np.save(sys.argv[3] + ".uv4.npy", arrays["meshes/4/uv/0"])
json.dump(d, open(sys.argv[3], "w"), indent=1, sort_keys=True)
