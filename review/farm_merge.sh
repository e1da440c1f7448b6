#!/bin/bash
# Two pass chunks of one .blend frame, then stpm merge (the docs/cli.md farm recipe): python-free shell steps
cd "$(dirname "$0")/.."; export PYTHONPATH="$PWD"; S=${STPM:-.venv/bin/stpm}   # the checkout's (python3 build.py demo makes .venv)
B=${1:-review/out/kitchen.blend}; F=${2:-2}; O=review/out/farm2; mkdir -p $O
$S render $B --frame $F --method progressive --pass-offset 0 --passes 4 --samples 1 --photons-global 20000 --photons-caustic 20000 -o $O/part_a.exr --quiet; echo rc=$?
$S render $B --frame $F --method progressive --pass-offset 4 --passes 4 --samples 1 --photons-global 20000 --photons-caustic 20000 -o $O/part_b.exr --quiet; echo rc=$?
$S merge $O/part_a.exr $O/part_b.exr -o $O/merged.exr; echo rc=$?
