#!/usr/bin/env bash
# The CUDA checks on a GPU machine, in one run (about 9 minutes): unpacks tools/gpu_extras.sh's extras (the
# denoiser from $OIDN_TAR, the sm_90 PTX), then runs, each under its own limit, writing under $OUT:
#   the cuda-parametrized tests (pytest_cuda.txt), the default technique on the demo at 384x256 and on a storm
#   frame at 512 wide with a 20 s budget (EXR headers printed), and a 48-frame storm simulation on cuda:0.
# Usage there: OIDN_TAR=/root/stash/oidn.tar.xz bash tools/gpu_run.sh   (Python packages already on PYTHONPATH)
set -u
T0=$SECONDS; OUT=${OUT:-out/gpu-run}; mkdir -p "$OUT"
left() { echo $(( ${GPU_RUN_SECONDS:-570} - (SECONDS - T0) )); }
limit() { local t=$(( $(left) - $2 )); [ "$t" -gt "$1" ] && t=$1; echo "$t"; }
site=$(python3 -c "import sys; print(next(p for p in sys.path if p.endswith('site') and 'tmp' in p))" 2>/dev/null || echo /tmp/site)
[ -f "${OIDN_TAR:-}" ] && tar -xJf "$OIDN_TAR" -C "$site"
cache=/root/.cache/warp/1.19.0; mkdir -p $cache && tar -xJf .gpu-payload/extras/ptx.tar.xz -C $cache
export PYTHONPATH=$PWD/.gpu-payload/extras:$PYTHONPATH PYTHONUNBUFFERED=1
python3 -c "import pyoidn, warp; print('pyoidn', pyoidn.__file__)" || echo "no pyoidn: the default technique will refuse to denoise"
n0=$(ls $cache | wc -l)
timeout "$(limit 300 200)" python3 -m pytest -q -p no:cacheprovider -k cuda --maxfail=30 --durations=10 -rfE \
  > "$OUT/pytest_cuda.txt" 2>&1; echo "tests: $(tail -1 "$OUT/pytest_cuda.txt")"
echo "modules compiled here: $(( $(ls $cache | wc -l) - n0 ))"
header() { python3 -c "import OpenEXR, glob, sys
for f in glob.glob(sys.argv[1]):
    h = OpenEXR.File(f).header()
    print(f, {k[8:]: h[k] for k in sorted(h) if k[8:] in ('technique', 'renderSeconds', 'spp', 'paths', 'errorEstimate', 'stoppedBy')})" "$1"; }
s=$SECONDS; timeout "$(limit 90 110)" python3 -m warpsky render usd_scenes/cumulus.usda "$OUT/demo.####.exr" --frames 1 \
  --res 384x256 --device cuda:0 > "$OUT/demo.txt" 2>&1; echo "demo rc $? in $((SECONDS - s)) s"; header "$OUT/demo.*.exr"
s=$SECONDS; timeout "$(limit 60 60)" python3 -m warpsky render usd_scenes/storm.usda "$OUT/storm.####.exr" --frames 40 \
  --res 512 --device cuda:0 --time-budget 20 > "$OUT/storm.txt" 2>&1; echo "storm rc $? in $((SECONDS - s)) s"
header "$OUT/storm.*.exr"
s=$SECONDS; timeout "$(limit 150 5)" python3 -m warpsky simulate --out /tmp/sim --device cuda:0 > "$OUT/simulate.txt" 2>&1
echo "simulate rc $? in $((SECONDS - s)) s"; tail -3 "$OUT/simulate.txt"
grep -E "FAILED|ERROR" "$OUT/pytest_cuda.txt" | cut -c1-200 | head -30
mkdir -p /tmp/keep && mv "$OUT"/*.exr /tmp/keep/ 2>/dev/null; tar -C "$OUT" -czf /tmp/texts.tgz . && rm -rf "${OUT:?}"/* && mv /tmp/texts.tgz "$OUT/"
