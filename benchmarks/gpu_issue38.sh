#!/usr/bin/env bash
# The checks that need a GPU, as one prepared run on a lent machine (its image has jax,
# numpy, scipy, optax and matplotlib). Parts in order of priority, each with its own time
# limit, logged as they run (a part stopped at its limit still says how far it got):
#   1. issue 38: the F-16 fault-kind study at 10^4 flights per kind and view
#      (benchmarks/f16_fault_kinds.py; 160 000 flights of 15 s);
#   2. issue 36: runs per second of the studies not yet measured on a GPU, each
#      `jaxfdi run <study> --runs N` from an empty XLA cache, wall time end to end.
# Results go to $OUT (or benchmarks/gpu/ when OUT is unset): gpu38.log and the JSON files.
#   bash benchmarks/gpu_issue38.sh
# A CPU dry run: KIND_RUNS=2 STUDY_RUNS="vtol:2 gnss-campus:2" bash benchmarks/gpu_issue38.sh
set -u
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD"
out="${OUT:-benchmarks/gpu}"
mkdir -p "$out"
log="$out/gpu38.log"
{ nvidia-smi -L 2>&1; python3 -c "import jax, numpy; print('jax', jax.__version__, jax.default_backend(), jax.devices(), 'numpy', numpy.__version__)"
  lscpu | grep -E "Model name|^CPU\(s\)"; } 2>&1 | tee "$log"

echo "== 1. F-16 fault kinds, ${KIND_RUNS:-10000} flights per kind and view" | tee -a "$log"
export JAXFDI_CACHE_DIR="$(mktemp -d)"
timeout "${KIND_LIMIT:-240}" python3 benchmarks/f16_fault_kinds.py --runs "${KIND_RUNS:-10000}" --chunk 0 \
  --out "$out/results_f16_fault_kinds_gpu.json" 2>&1 | grep -v Warning | tee -a "$log"

echo "== 2. studies at scale, empty cache, end to end" | tee -a "$log"
for pair in ${STUDY_RUNS:-f16-flight:10000 gnss-campus:10000 vtol:2000 reaction-wheels:1000}; do
  study="${pair%%:*}"; runs="${pair##*:}"
  export JAXFDI_CACHE_DIR="$(mktemp -d)"
  start=$EPOCHREALTIME
  timeout "${STUDY_LIMIT:-50}" python3 -m jaxfdi run "$study" --runs "$runs" --quiet --out "/tmp/gpu38_$study" \
    > "/tmp/gpu38_$study.log" 2>&1
  rc=$?
  wall=$(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$start" "$EPOCHREALTIME")
  echo "$study --runs $runs: rc $rc, $wall s end to end" | tee -a "$log"
  grep -v Warning "/tmp/gpu38_$study.log" | tail -3 | tee -a "$log"
done
echo "gpu_issue38 done" | tee -a "$log"
