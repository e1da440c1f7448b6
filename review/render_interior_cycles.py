"""Cycles on review/out/interior.blend, frame 12: python review/render_interior_cycles.py SPP [TAG] [--time-limit S]
CPU, no denoising, no adaptive sampling, clamps off (Cycles' unbiased answer; the tests' settings). Max bounces
left at the file's (Cycles' defaults: 12 total, diffuse 4, glossy 4, transmission 12). Writes
review/out/interior_cycles_<TAG>.exr and prints the wall time."""
import sys
from _review_common import OUT, cycles_reference
cycles_reference(OUT / "interior.blend", 12, "interior_cycles", sys.argv[1:])
