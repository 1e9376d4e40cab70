#!/usr/bin/env bash
# The CUDA checks on a GPU machine, in one run of at most $GPU_RUN_SECONDS (570): unpacks tools/gpu_extras.sh's
# extras (the denoiser from $OIDN_TAR when given, the sm_90 PTX), then runs, each step under its own limit and
# skipped when too little time is left, writing under $OUT (packed into $OUT/texts.tgz at the end):
#   the cuda-parametrized tests (pytest_cuda.txt); the default technique on the demo at 384x256 and on a storm
#   frame at 512 wide with a 20 s budget (their EXR headers printed); a 48-frame storm simulation.
# Usage there, with the Python packages already on PYTHONPATH:
#   OIDN_TAR=/root/stash/oidn.tar.xz bash tools/gpu_run.sh        (GPU_RUN_DEVICE=cpu tries it on a CPU)
set -u
T0=$SECONDS; OUT=${OUT:-out/gpu-run}; DEVICE=${GPU_RUN_DEVICE:-cuda:0}; mkdir -p "$OUT"
# step LIMIT RESERVE NAME COMMAND...: run COMMAND under min(LIMIT, time left - RESERVE) seconds, or skip it
step() {
  local most=$1 t=$(( ${GPU_RUN_SECONDS:-570} - (SECONDS - T0) - $2 )) name=$3 s=$SECONDS; shift 3
  [ "$t" -gt "$most" ] && t=$most
  [ "$t" -lt 10 ] && { echo "$name: skipped (too little time left)"; return; }
  timeout "$t" "$@" > "$OUT/$name.txt" 2>&1; echo "$name: exit $? in $((SECONDS - s)) s (limit $t s)"
}
header() { python3 -c "import OpenEXR, glob, sys
for f in sorted(glob.glob(sys.argv[1])):
    h = OpenEXR.File(f).header()
    keys = ('technique', 'renderSeconds', 'spp', 'paths', 'errorEstimate', 'stoppedBy')
    print(f, {k: h.get('warpsky/' + k) for k in keys})" "$1"; }
site=$(python3 -c "import sys; print(next(p for p in sys.path if p.startswith('/tmp') and p.endswith('site')))" \
  2>/dev/null || echo /tmp/site)
[ -f "${OIDN_TAR:-}" ] && tar -xJf "$OIDN_TAR" -C "$site"
cache=$(python3 -c "import warp as wp; wp.config.quiet = True; wp.init(); print(wp.config.kernel_cache_dir)" | tail -1)
[ -f .gpu-payload/extras/ptx.tar.xz ] && mkdir -p "$cache" && tar -xJf .gpu-payload/extras/ptx.tar.xz -C "$cache"
export PYTHONPATH=$PWD/.gpu-payload/extras:${PYTHONPATH:-} PYTHONUNBUFFERED=1
python3 -c "import pyoidn" 2>/dev/null && echo "pyoidn: yes" || echo "pyoidn: no (the default technique refuses)"
n0=$(ls "$cache" | wc -l)
step 300 200 pytest_cuda python3 -m pytest -q -p no:cacheprovider -k cuda --maxfail=30 --durations=10 -rfE
echo "  $(tail -1 "$OUT/pytest_cuda.txt")"; echo "  modules compiled here: $(( $(ls "$cache" | wc -l) - n0 ))"
step 90 110 demo python3 -m warpsky render usd_scenes/cumulus.usda "$OUT/demo.####.exr" --frames 1 --res 384x256 \
  --device "$DEVICE"
header "$OUT/demo.*.exr"
step 60 60 storm python3 -m warpsky render usd_scenes/storm.usda "$OUT/storm.####.exr" --frames 40 --res 512 \
  --device "$DEVICE" --time-budget 20
header "$OUT/storm.*.exr"
step 150 5 simulate python3 -m warpsky simulate --out /tmp/gpu-run-sim --device "$DEVICE"
tail -2 "$OUT/simulate.txt"
grep -E "FAILED|ERROR" "$OUT/pytest_cuda.txt" | cut -c1-200 | head -30
mkdir -p /tmp/gpu-run-exr && mv "$OUT"/*.exr /tmp/gpu-run-exr/ 2>/dev/null
tar -C "$OUT" -czf /tmp/gpu-run-texts.tgz . && rm -rf "${OUT:?}"/* && mv /tmp/gpu-run-texts.tgz "$OUT/texts.tgz"
