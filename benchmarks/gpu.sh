#!/usr/bin/env bash
# The measurements that need a GPU, as one prepared run on a lent machine (its image has jax,
# numpy, scipy, optax and matplotlib; nothing else is needed). Parts in order of priority, each
# with its own time limit so that one slow part cannot take the others' time (about 9 minutes
# in all), logged as they run (a part stopped at its limit still says how far it got):
#   1. `jaxfdi run engine --runs 100000` end to end from an empty XLA cache, then again warm
#      (target: at most 60 s);
#   2. every study's default CLI run at 10^4 runs per case, cold and warm, wall seconds and
#      the study's own seconds (benchmarks/bench_studies.py);
#   3. the F-16 hybrid FDI at 10^6 flights through the study engine's chunks
#      (benchmarks/gpu_scale.py).
# Results go to $OUT (or benchmarks/gpu/ when OUT is unset): device.txt (the card), gpu.log,
# results_studies_gpu.json and the engine study's JSON.
#   bash benchmarks/gpu.sh
# A CPU dry run of the script (small sizes, one study):
#   ENGINE_RUNS=2 STUDY_RUNS=2 STUDIES=engine-chi2 FLIGHTS=64 CHUNK=64 bash benchmarks/gpu.sh
set -u
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD"
out="${OUT:-benchmarks/gpu}"
mkdir -p "$out"
log="$out/gpu.log"
elapsed() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$EPOCHREALTIME"; }
{ nvidia-smi -L 2>&1; python3 -c "import jax, numpy; print('jax', jax.__version__, jax.default_backend(), jax.devices(), 'numpy', numpy.__version__)"
  lscpu | grep -E "Model name|^CPU\(s\)"; } 2>&1 | tee "$out/device.txt" > "$log"

export JAXFDI_CACHE_DIR="$(mktemp -d)"
for pass in cold warm; do
  echo "== 1. jaxfdi run engine --runs ${ENGINE_RUNS:-100000}, $pass cache" | tee -a "$log"
  start=$EPOCHREALTIME
  timeout "${ENGINE_LIMIT:-110}" python3 -m jaxfdi run engine --runs "${ENGINE_RUNS:-100000}" --out "$out/engine_$pass" 2>&1 \
    | grep -v Warning | tee -a "$log"
  echo "engine, $pass: $(elapsed "$start") s end to end (rc ${PIPESTATUS[0]})" | tee -a "$log"
done

echo "== 2. every study's default CLI run at ${STUDY_RUNS:-10000} runs per case, cold and warm" | tee -a "$log"
timeout "${STUDIES_LIMIT:-240}" python3 benchmarks/bench_studies.py --runs "${STUDY_RUNS:-10000}" --timeout "${STUDY_LIMIT:-30}" \
  --studies ${STUDIES:-vtol f16-flight engine-chi2 gnss-campus reaction-wheels gps-ins f16} \
  --out "$out/results_studies_gpu.json" 2>&1 | grep -v Warning | tee -a "$log"

echo "== 3. F-16 hybrid FDI at ${FLIGHTS:-1000000} flights" | tee -a "$log"
export JAXFDI_CACHE_DIR="$(mktemp -d)"
timeout "${SCALE_LIMIT:-90}" python3 benchmarks/gpu_scale.py --flights "${FLIGHTS:-1000000}" --single ${CHUNK:+--chunk $CHUNK} 2>&1 \
  | grep -v Warning | tee -a "$log"
echo "gpu.sh done" | tee -a "$log"
