#!/usr/bin/env bash
# Everything that needs a GPU, in one go (about 6 minutes on an H100):
#   bash benchmarks/gpu_all.sh OUT_DIR [SIZES]
# builds the one-thread-per-chain CUDA kernels the tests and the benchmark use (in parallel),
# runs the tests that compare them with the JAX kernel on the GPU (GPU_TESTS=0 skips them),
# then benchmarks/gpu_kernel.py (sweeps against a plain CUDA kernel) and
# benchmarks/fit_bench.py's paper case twice: on the GPU, and on 2 of the machine's CPU cores
# (taskset, JAX on the CPU). Logs and the JSON files (seven files) go to OUT_DIR.
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
# the chain lengths of the tests (10 beads: 12 rows; with two sensor beads: 14) and of the bench (21: 23)
for rows in 12 14 23; do
  "$python" -c "from hertzchain import native; native._thread_library('cuda', $rows)" > "$out/build_$rows.tmp" 2>&1 &
done
JAX_PLATFORMS=cpu "$python" -m hertzchain kernel > "$out/build_host.tmp" 2>&1 &
wait
cat "$out"/build_*.tmp > "$out/builds.log" && rm -f "$out"/build_*.tmp
echo "builds: $(( $(date +%s) - start )) s" | tee -a "$out/gpu.txt"
if [ "${GPU_TESTS:-1}" != 0 ]; then
  "$python" -m pytest -q -p no:cacheprovider -m "" -W default tests/test_thread_kernel.py \
    -k "forces or (derivatives and not of_vmap) or fit_iteration or too_many" \
    2>&1 | tee "$out/tests.log" | tail -25
  echo "tests: $(( $(date +%s) - start )) s" | tee -a "$out/gpu.txt"
fi
"$python" benchmarks/gpu_kernel.py --out "$out/gpu_kernel.json" --sizes "$sizes" --budget-s 330 --skip-fit \
  2>&1 | tee "$out/bench.log"
echo "sweeps: $(( $(date +%s) - start )) s" | tee -a "$out/gpu.txt"
"$python" benchmarks/fit_bench.py --cases paper --label "GPU: $(nvidia-smi --query-gpu=name --format=csv,noheader)" \
  --out "$out/fit_bench_gpu.json" 2>&1 | tail -5 | tee -a "$out/bench.log"
JAX_PLATFORMS=cpu taskset -c 0,1 "$python" benchmarks/fit_bench.py --cases paper \
  --label "2 CPU cores (taskset) of the GPU machine" --out "$out/fit_bench_cpu2.json" 2>&1 | tail -5 | tee -a "$out/bench.log"
rm -f "$out"/fit_bench_*.md  # (rewritten from the JSON with fit_bench.py --table-from)
echo "all: $(( $(date +%s) - start )) s" | tee -a "$out/gpu.txt"
