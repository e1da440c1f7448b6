"""Cycles on review/out/outdoor.blend, frame 10: python review/render_outdoor_cycles.py SPP [TAG] [--time-limit S]
CPU, no denoising, no adaptive sampling, clamps off (Cycles' unbiased answer; the tests' settings). Max bounces
left at the file's (Cycles' defaults: 12 total, diffuse 4, glossy 4, transmission 12). Writes
review/out/outdoor_cycles_<TAG>.exr (--file NAME: review/out/NAME.blend) and prints the wall time."""
import sys
from _review_common import OUT, cycles_reference
name = sys.argv[sys.argv.index("--file") + 1] if "--file" in sys.argv else "outdoor"
cycles_reference(OUT / f"{name}.blend", 10, "outdoor_cycles", sys.argv[1:])
