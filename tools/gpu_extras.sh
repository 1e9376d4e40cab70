#!/usr/bin/env bash
# What a GPU machine without a package index needs beyond Warp, USD and OpenEXR to run the CUDA checks quickly
# (run here, in the repository root; tools/gpu_run.sh is the command to run there):
#   .gpu-payload/extras/ptx.tar.xz    every kernel module's sm_90 PTX from Warp's kernel cache (compiled here by
#                                     tests/test_cuda_codegen.py), so the GPU loads it instead of compiling
#                                     each module with NVRTC on one core (the 76 modules: 38 MB, 4.6 MB packed)
#   .gpu-payload/extras/oidn.tar.xz   pyoidn and cffi without OIDN's HIP and SYCL devices (the wheel is 88 MB,
#                                     over a call's 64 MiB), so the default technique can denoise there
#   .gpu-payload/extras/sitecustomize.py  sets warp.config.ptx_target_arch = 90 (Warp's default PTX target is
#                                     sm_75, whose cache entries the sm_90 PTX would not match)
# On an H100 with the PTX unpacked, 6 modules were compiled there (Warp's own and the tests'; 76 cache entries
# before, 82 after 141 cuda tests, the speed benchmark and four renders).
set -euo pipefail
out=.gpu-payload/extras; mkdir -p "$out"; work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
py=${PYTHON:-.venv/bin/python}
"$py" - "$work/ptx.list" "$work/cache" <<'PY'
import os, sys
import warp as wp
wp.config.quiet = True
from warpsky.cli.kernel_registry import compile_ptx, kernel_modules
folders = []
for index, module in enumerate(kernel_modules()):
    ptx = [p for p in compile_ptx(index, None, 90) if p.endswith(".ptx")]
    folders += [os.path.relpath(os.path.dirname(p), wp.config.kernel_cache_dir) for p in ptx]
open(sys.argv[1], "w").write("\n".join(folders))
open(sys.argv[2], "w").write(wp.config.kernel_cache_dir)
print(f"{len(folders)} modules' sm_90 PTX")
PY
tar -C "$(cat "$work/cache")" -cf - $(cat "$work/ptx.list") | xz -T2 -6 > "$out/ptx.tar.xz"
version=$("$py" -c "import importlib.metadata as m; print(m.version('pyoidn'))")
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 -d "$work/whl" "pyoidn==$version" cffi pycparser
mkdir -p "$work/site"; for w in "$work"/whl/*.whl; do (cd "$work/site" && unzip -qo "$w"); done
lib="$work/site/pyoidn/oidn/lib"
rm -f "$lib"/*hip* "$lib"/*sycl* "$lib"/libur_* "$lib"/libumf* "$lib"/libtbbbind*
for f in "$lib"/*.so*; do  # the wheel stores symbolic links as copies: make them links again
  real=$(ls "$lib"/$(basename "$f" | sed -E 's/\.so.*$//').so.* 2>/dev/null | sort | tail -1)
  [ -n "$real" ] && [ "$f" != "$real" ] && cmp -s "$f" "$real" && ln -sf "$(basename "$real")" "$f"
done
tar -C "$work/site" -cf - . | xz -T2 -6 > "$out/oidn.tar.xz"
printf '%s\n' "# Load the sm_90 PTX compiled ahead on the CPU machine (Warp's default PTX target is sm_75)." \
  "try:" "    import warp" "    warp.config.ptx_target_arch = 90" "except Exception:" "    pass" > "$out/sitecustomize.py"
du -sh "$out"/*
