#!/usr/bin/env bash
# The GPU check of fit_btf (benchmarks/bench_btf.py --device), as run on a lent accelerator: the machine's
# own JAX (no project venv), the compile cache in /tmp, results under $OUT when set.
set -u
export PYTHONPATH=$PWD PYTHONUNBUFFERED=1 BRDFFIT_CACHE=${BRDFFIT_CACHE:-/tmp/brdffit-cache} XLA_PYTHON_CLIENT_PREALLOCATE=false
OUT=${OUT:-/tmp}
nvidia-smi --query-gpu=name,memory.total,clocks.sm --format=csv 2>/dev/null
python3 -c "import jax, optimistix; print('jax', jax.__version__, jax.devices())"
timeout ${SMALL_S:-150} python3 benchmarks/bench_btf.py --size 64 --loop 0 --device 2>&1 | tee $OUT/bench64.txt
timeout ${LARGE_S:-330} python3 benchmarks/bench_btf.py --size ${SIZE:-256} --loop 0 --device 2>&1 | tee $OUT/bench256.txt
# The CPU path on two of this machine's cores (a quiet, controlled stand-in for a 2-core machine).
if [ -n "${CPU2:-}" ]; then
    JAX_PLATFORMS=cpu timeout ${CPU_S:-200} taskset -c 0,1 python3 benchmarks/bench_btf.py --size 64 --loop 32 2>&1 | tee $OUT/cpu64.txt
fi
