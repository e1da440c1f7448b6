#!/bin/sh
# The CLI on the bottle: two pass chunks + merge against one process, a time limit, a plan.
# sh review/cli_bottle.sh   (from the checkout; makes review/out/cli/)
set -x
D=review/out/cli; mkdir -p $D; cp review/out/bottle.blend review/out/bottle_cli.blend   # same folder: the textures are relative (//bottle_textures)
S="env PYTHONPATH=. /work/main/.venv/bin/python -m stpm_core.cli"
O="--frame 3 --method progressive --photons-global 20000 --photons-caustic 50000 --samples 1 --quiet"
$S plan review/out/bottle_cli.blend --frame 3 --json
$S render review/out/bottle_cli.blend $O --pass-offset 0 --passes 4 -o $D/part_a.exr --stats $D/part_a.json
$S render review/out/bottle_cli.blend $O --pass-offset 4 --passes 4 -o $D/part_b.exr
$S render review/out/bottle_cli.blend $O --passes 8 -o $D/full8.exr
$S merge $D/part_a.exr $D/part_b.exr -o $D/merged.exr
$S merge $D/part_a.exr $D/part_a.exr -o $D/merged_overlap.exr; echo "overlap exit $?"
$S render review/out/bottle_cli.blend --frame 3 --method progressive --passes 0 --time-limit 20 --quiet -o $D/tl20.exr --stats $D/tl20.json
