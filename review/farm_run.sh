#!/bin/bash
# Scene 3: a farm-style run on review/out/kitchen.blend (progressive, frames, time limit, pass chunks + merge)
set -x
cd "$(dirname "$0")/.."; export PYTHONPATH="$PWD"; S=${STPM:-.venv/bin/stpm}   # the checkout's (python3 build.py demo makes .venv)
mkdir -p review/out/farm
time $S render review/out/kitchen.blend --frame 1-2 --method progressive --time-limit 20 --samples 1 --photons-global 20000 --photons-caustic 20000 --output 'review/out/farm/tl_####.exr' --quiet; echo rc=$?
time $S render review/out/kitchen.blend --frame 2 --method progressive --pass-offset 0 --passes 4 --samples 1 --photons-global 20000 --photons-caustic 20000 -o review/out/farm/part_a.exr --quiet; echo rc=$?
time $S render review/out/kitchen.blend --frame 2 --method progressive --pass-offset 4 --passes 4 --samples 1 --photons-global 20000 --photons-caustic 20000 -o review/out/farm/part_b.exr --quiet; echo rc=$?
time $S merge review/out/farm/part_a.exr review/out/farm/part_b.exr -o review/out/farm/merged.exr; echo rc=$?
time $S render review/out/kitchen.blend --frame 2 --method progressive --passes 8 --samples 1 --photons-global 20000 --photons-caustic 20000 -o review/out/farm/whole.exr --quiet; echo rc=$?
