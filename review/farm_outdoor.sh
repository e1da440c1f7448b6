#!/bin/bash
# Artist review 4, the farm TD's part on review/out/outdoor.blend (frame 10): pass chunks + merge
# against one process, Ctrl-C and SIGTERM during a render, `stpm render` of the bad-input file.
cd "$(dirname "$0")/.."; export PYTHONPATH="$PWD"; S=${STPM:-/work/main/.venv/bin/stpm}
B=review/out/outdoor.blend; O=review/out/farm4; rm -rf $O; mkdir -p $O
P="--frame 10 --method progressive --samples 1 --photons-global 20000 --photons-caustic 20000 --resolution 120x68 --quiet"
for a in "0 4" "4 4"; do set -- $a
  /usr/bin/time -f "chunk $1+$2: %e s" $S render $B $P --pass-offset $1 --passes $2 -o $O/part_$1.exr; echo rc=$?
done
/usr/bin/time -f "merge: %e s" $S merge $O/part_0.exr $O/part_4.exr -o $O/merged.exr; echo rc=$?
/usr/bin/time -f "whole 8: %e s" $S render $B $P --passes 8 -o $O/whole.exr --stats $O/whole.json; echo rc=$?
/work/main/.venv/bin/python - <<'PY'
import OpenImageIO as oiio, numpy as np
def layers(p):
    i = oiio.ImageInput.open(p); out = {}; sub = 0
    while i.seek_subimage(sub, 0):
        s = i.spec(); px = i.read_image(sub, 0, 0, s.nchannels, "float").reshape(s.height, s.width, -1)
        out.update({n: px[..., c] for c, n in enumerate(s.channelnames) if not n.startswith("STPMSum")}); sub += 1
    return out
a, b = layers("review/out/farm4/merged.exr"), layers("review/out/farm4/whole.exr")
print("merged vs whole:", len(a), "channels; same names", sorted(a) == sorted(b),
      "; bit-equal", all(np.array_equal(a[n], b[n]) for n in b), "; max |diff|", max(float(np.abs(a[n] - b[n]).max()) for n in b))
PY
# Cancel: SIGINT and SIGTERM 25 s into a long render; no output may be left
for sig in INT TERM; do
  $S render $B --frame 10 --samples 4096 --resolution 120x68 -o $O/cancel_$sig.exr --quiet & pid=$!
  sleep 25; kill -$sig $pid; t=$(date +%s.%N); wait $pid; rc=$?; echo "SIG$sig: rc=$rc after $(echo "$(date +%s.%N) - $t" | bc) s"; ls -a $O | grep -i cancel || echo "no cancel outputs left"
done
$S render review/out/outdoor_bad.blend --frame 10 --samples 1 --photons-global 2000 --photons-caustic 2000 --resolution 60x34 -o $O/bad.exr; echo "bad file: rc=$?"
$S render review/out/no_such.blend -o $O/x.exr; echo "missing file: rc=$?"
