# The farm TD's checks on one review file, sourced by farm_interior.sh and farm_outdoor.sh, which set
# S (the stpm command), B (the .blend), O (an empty output folder) and P (the chunked render's options).

# Pass chunks 0+4 and 4+4 of `stpm render $B $P`, `stpm merge` of the two, the 8 passes in one process,
# and whether the merge is bit-equal to it (the STPMSum* bookkeeping channels left out)
farm_chunks() {
  for a in "0 4" "4 4"; do set -- $a
    /usr/bin/time -f "chunk $1+$2: %e s" $S render $B $P --pass-offset $1 --passes $2 -o $O/part_$1.exr; echo rc=$?
  done
  /usr/bin/time -f "merge: %e s" $S merge $O/part_0.exr $O/part_4.exr -o $O/merged.exr; echo rc=$?
  /usr/bin/time -f "whole 8: %e s" $S render $B $P --passes 8 -o $O/whole.exr --stats $O/whole.json; echo rc=$?
  /work/main/.venv/bin/python - "$O" <<'PY'
import sys
import OpenImageIO as oiio, numpy as np
def layers(p):
    i = oiio.ImageInput.open(p); out = {}; sub = 0
    while i.seek_subimage(sub, 0):
        s = i.spec(); px = i.read_image(sub, 0, 0, s.nchannels, "float").reshape(s.height, s.width, -1)
        out.update({n: px[..., c] for c, n in enumerate(s.channelnames) if not n.startswith("STPMSum")}); sub += 1
    return out
a, b = layers(f"{sys.argv[1]}/merged.exr"), layers(f"{sys.argv[1]}/whole.exr")
print("merged vs whole:", len(a), "channels; same names", sorted(a) == sorted(b),
      "; bit-equal", all(np.array_equal(a[n], b[n]) for n in b), "; max |diff|", max(float(np.abs(a[n] - b[n]).max()) for n in b))
PY
}

# Cancel: SIGINT and SIGTERM 25 s into `stpm render $B ARGS...` (a long render); no output may be left
farm_cancel() {
  for sig in INT TERM; do
    $S render $B "$@" -o $O/cancel_$sig.exr --quiet & pid=$!
    sleep 25; kill -$sig $pid; t=$(date +%s.%N); wait $pid; rc=$?; echo "SIG$sig: rc=$rc after $(echo "$(date +%s.%N) - $t" | bc) s"; ls -a $O | grep -i cancel || echo "no cancel outputs left"
  done
}
