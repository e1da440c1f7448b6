#!/bin/bash
# Artist review 3, the farm TD's part on review/out/interior.blend (frame 12): pass chunks + merge
# against one process, stpm compare with a time budget, Ctrl-C and SIGTERM during a render.
cd "$(dirname "$0")/.."; export PYTHONPATH="$PWD"; S=${STPM:-/work/main/.venv/bin/stpm}
. review/farm_checks.sh
B=review/out/interior.blend; O=review/out/farm3; rm -rf $O; mkdir -p $O
P="--frame 12 --method progressive --samples 1 --photons-global 20000 --photons-caustic 20000 --resolution 160x90 --quiet"
farm_chunks
farm_cancel --frame 12 --samples 64 --resolution 160x90
/usr/bin/time -f "compare: %e s" $S compare $B --frame 12 --resolution 80x45 --samples 2 --photons-global 10000 --photons-caustic 10000 --time-budget 60 --output $O/compare; echo rc=$?
ls $O/compare
