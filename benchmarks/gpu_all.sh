#!/usr/bin/env bash
# Everything that needs a GPU, in one go (about 6 minutes on an H100 or H200):
#   bash benchmarks/gpu_all.sh OUT_DIR [SIZES]
# builds the one-thread-per-chain CUDA kernels the tests and the benchmarks use (in parallel,
# with the build variants of benchmarks/gpu_variants.py), runs the tests that compare them
# with the JAX kernel on the GPU (GPU_TESTS=0 skips them), then benchmarks/gpu_variants.py
# (the build variants against a plain CUDA kernel), benchmarks/gpu_kernel.py (sweeps against
# that kernel), benchmarks/fit_bench.py's paper case on the GPU and on 2 of the machine's CPU
# cores (taskset, JAX on the CPU; FITS=0 skips both) and a short posterior on the GPU
# (benchmarks/posterior_bench.py, 4 chains x (POSTERIOR_WARMUP + POSTERIOR_DRAWS), 20 + 20 by
# default; POSTERIOR=0 skips it). At most eight files go to OUT_DIR: gpu.txt (the machine
# and each phase's time), builds_and_tests.log, bench.log and the JSON files.
set -uo pipefail
out=${1:?usage: gpu_all.sh OUT_DIR [SIZES]}
sizes=${2:-100000}
mkdir -p "$out"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
python=${PYTHON:-python3}
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv | tee "$out/gpu.txt"
nvcc --version | tail -2 | tee -a "$out/gpu.txt"
lscpu | grep -E "Model name|^CPU\(s\)|Flags" | cut -c1-400 >> "$out/gpu.txt"
start=$(date +%s)
phase() { echo "$1: $(( $(date +%s) - start )) s" | tee -a "$out/gpu.txt"; }
variants=$(mktemp -d)
# the chain lengths of the tests (10 beads: 12 rows; with two sensor beads: 14) and of the bench (21: 23)
for rows in 12 14 23; do
  "$python" -c "from hertzchain import native; native._thread_library('cuda', $rows)" > "$out/build_$rows.tmp" 2>&1 &
done
JAX_PLATFORMS=cpu "$python" -m hertzchain kernel > "$out/build_host.tmp" 2>&1 &
"$python" benchmarks/gpu_variants.py --cache-root "$variants" --build-only > "$out/build_variants.tmp" 2>&1 &
wait
cat "$out"/build_*.tmp > "$out/builds_and_tests.log" && rm -f "$out"/build_*.tmp
phase builds
if [ "${GPU_TESTS:-1}" != 0 ]; then
  "$python" -m pytest -q -p no:cacheprovider -m "" -W default tests/test_thread_kernel.py \
    -k "forces or (derivatives and not of_vmap) or fit_iteration or too_many" \
    2>&1 | tee -a "$out/builds_and_tests.log" | tail -25
  phase tests
fi
timeout 300 "$python" benchmarks/gpu_variants.py --cache-root "$variants" --out "$out/gpu_variants.json" \
  --size "${sizes%%,*}" 2>&1 | tee "$out/bench.log"
phase variants
timeout 300 "$python" benchmarks/gpu_kernel.py --out "$out/gpu_kernel.json" --sizes "$sizes" --budget-s 200 --skip-fit \
  2>&1 | tee -a "$out/bench.log"
phase sweeps
if [ "${FITS:-1}" != 0 ]; then
  "$python" benchmarks/fit_bench.py --cases paper --label "GPU: $(nvidia-smi --query-gpu=name --format=csv,noheader)" \
    --out "$out/fit_bench_gpu.json" 2>&1 | tail -5 | tee -a "$out/bench.log"
  JAX_PLATFORMS=cpu taskset -c 0,1 "$python" benchmarks/fit_bench.py --cases paper \
    --label "2 CPU cores (taskset) of the GPU machine" --out "$out/fit_bench_cpu2.json" 2>&1 | tail -5 | tee -a "$out/bench.log"
  rm -f "$out"/fit_bench_*.md  # (rewritten from the JSON with fit_bench.py --table-from)
  phase fits
fi
if [ "${POSTERIOR:-1}" != 0 ] && ! "$python" -c "import arviz, numpyro" 2> /dev/null; then
  echo "posterior: skipped, it needs arviz and numpyro (pip install arviz numpyro)" | tee -a "$out/bench.log"
elif [ "${POSTERIOR:-1}" != 0 ]; then
  timeout "${POSTERIOR_TIMEOUT_S:-240}" "$python" benchmarks/posterior_bench.py --out "$out/posterior_gpu.json" \
    --warmup "${POSTERIOR_WARMUP:-20}" --draws "${POSTERIOR_DRAWS:-20}" 2>&1 | grep -v '^ ' | tail -20 | tee -a "$out/bench.log"
  phase posterior
fi
phase all
