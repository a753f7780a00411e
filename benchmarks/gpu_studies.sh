#!/usr/bin/env bash
# Issue 36's checks that need a GPU, as one prepared run on a lent machine (its image has
# jax, numpy, scipy, optax and matplotlib; nothing else is needed). Each part has its own
# time limit, in order of priority, and everything is logged as it happens, so a part
# stopped at its limit still says how far it got:
#   1. the engine's Table 3 study at 10^5 runs per fault, `jaxfdi run engine`, end to end
#      from an empty XLA cache (target: at most 60 s);
#   2. the F-16 hybrid FDI at 10^4 and 10^5 flights through the study engine's chunks, and
#      one batch of all flights at once with its memory (benchmarks/gpu_scale.py);
#   3. every study's default CLI run from an empty cache (benchmarks/bench_studies.py).
# Results go to $OUT (or benchmarks/gpu/ when OUT is unset): gpu.log, results_studies_gpu.json
# and the engine study's JSON.
#   bash benchmarks/gpu_studies.sh
# A CPU dry run of the script: ENGINE_RUNS=2 FLIGHTS=64 SINGLE=64 CHUNK=64 STUDIES=engine-chi2 bash benchmarks/gpu_studies.sh
set -u
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD"
out="${OUT:-benchmarks/gpu}"
mkdir -p "$out"
log="$out/gpu.log"
elapsed() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$EPOCHREALTIME"; }
{ nvidia-smi -L 2>&1; python3 -c "import jax, numpy; print('jax', jax.__version__, jax.default_backend(), jax.devices(), 'numpy', numpy.__version__)"
  lscpu | grep -E "Model name|^CPU\(s\)"; } 2>&1 | tee "$log"

echo "== 1. jaxfdi run engine --runs ${ENGINE_RUNS:-100000}, empty cache" | tee -a "$log"
export JAXFDI_CACHE_DIR="$(mktemp -d)"
start=$EPOCHREALTIME
timeout "${ENGINE_LIMIT:-120}" python3 -m jaxfdi run engine --runs "${ENGINE_RUNS:-100000}" --out /tmp/engine_out 2>&1 \
  | grep -v Warning | tee -a "$log"
echo "engine end to end: $(elapsed "$start") s (rc ${PIPESTATUS[0]})" | tee -a "$log"
cp /tmp/engine_out/*.json "$out/" 2>/dev/null

echo "== 2. F-16 hybrid FDI at scale" | tee -a "$log"
export JAXFDI_CACHE_DIR="$(mktemp -d)"
timeout "${SCALE_LIMIT:-130}" python3 benchmarks/gpu_scale.py --flights ${FLIGHTS:-10000 100000} \
  --single ${SINGLE:-30000 100000} ${CHUNK:+--chunk $CHUNK} 2>&1 | grep -v Warning | tee -a "$log"

echo "== 3. every study's default CLI run, empty cache" | tee -a "$log"
timeout "${STUDIES_LIMIT:-280}" python3 benchmarks/bench_studies.py --cold-only --timeout "${STUDY_LIMIT:-45}" \
  --studies ${STUDIES:-engine vtol f16-flight engine-chi2 gnss-campus reaction-wheels gps-ins f16} \
  --out "$out/results_studies_gpu.json" 2>&1 | grep -v Warning | tee -a "$log"
echo "gpu_studies done" | tee -a "$log"
