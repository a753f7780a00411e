#!/usr/bin/env bash
# The benchmarks that need a GPU, as one prepared run on a lent machine. It has no package
# registry, and bench_scale.py imports bench_filters.py, which imports filterpy and dynamax:
# they and dynamax's needs that machine lacks travel as wheels in .whl/ (git-ignored), made
# beforehand where pip works (the 2026-11-26 run used exactly these):
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
#     -d .whl filterpy==2.0.0 dynamax==1.0.3 tfp-nightly fastprogress==1.0.3 decorator gast dm-tree
# Each part has its own time limit so that one slow part cannot take the others' time;
# results go to $OUT (or benchmarks/gpu/ when OUT is unset).
#   bash benchmarks/gpu_session.sh
set -u
export PYTHONUNBUFFERED=1
out="${OUT:-benchmarks/gpu}"
mkdir -p "$out"
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH="/tmp/site:$PWD" || exit 1
else
  export PYTHONPATH="$PWD"
fi
nvidia-smi -L 2>&1 | tee "$out/device.txt"
python3 -c "import jax, numpy; print('jax', jax.__version__, jax.default_backend(), jax.devices(), 'numpy', numpy.__version__)" 2>&1 | tee -a "$out/device.txt"
lscpu | grep -E "Model name|^CPU\(s\)" | tee -a "$out/device.txt"

# issue 23: closed-loop F-16 flights per second, jaxfdi on the GPU vs the NumPy loop on this machine's CPU
timeout "${F16_LIMIT:-230}" python3 benchmarks/bench_f16_flight.py --flights 1 100 10000 100000 --numpy-flights 3 \
  --repeats 3 --dtype both --gradient-flights 0 --out "$out/results_f16_flight_gpu.json" 2>&1 | grep -v Warning | tee "$out/f16_flight.log"
# issue 29: associative-scan vs sequential KF (and RTS) for T = 10^3..10^5
timeout "${SCALE_LIMIT:-170}" python3 benchmarks/bench_scale.py --only parallel --skip-eager --repeats 5 --budget 5 \
  --cases "${SCALE_CASES:-1x1000,1x100000,1x10000,100x10000}" --out "$out/results_scale_gpu.json" 2>&1 \
  | grep -v Warning | tee "$out/scale.log"
# issue 24: the hybrid FDI flight at scale
timeout "${FDI_LIMIT:-150}" python3 benchmarks/bench_f16_fdi.py --flights 10000 --numpy-flights 2 --repeats 3 \
  --out "$out/results_f16_fdi_gpu.json" 2>&1 | grep -v Warning | tee "$out/f16_fdi.log"
echo "gpu_session done"
