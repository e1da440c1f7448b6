#!/bin/bash
# Artist review 4, the farm TD's part on review/out/outdoor.blend (frame 10): pass chunks + merge
# against one process, Ctrl-C and SIGTERM during a render, `stpm render` of the bad-input file.
cd "$(dirname "$0")/.."; export PYTHONPATH="$PWD"; S=${STPM:-/work/main/.venv/bin/stpm}
. review/farm_checks.sh
B=review/out/outdoor.blend; O=review/out/farm4; rm -rf $O; mkdir -p $O
P="--frame 10 --method progressive --samples 1 --photons-global 20000 --photons-caustic 20000 --resolution 120x68 --quiet"
farm_chunks
farm_cancel --frame 10 --samples 4096 --resolution 120x68
$S render review/out/outdoor_bad.blend --frame 10 --samples 1 --photons-global 2000 --photons-caustic 2000 --resolution 60x34 -o $O/bad.exr; echo "bad file: rc=$?"
$S render review/out/no_such.blend -o $O/x.exr; echo "missing file: rc=$?"
