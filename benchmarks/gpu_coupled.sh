#!/usr/bin/env bash
# The coupled thermo-mechanical step on a GPU: 1e4 to 1e6 particles, 200 steps, float64 and float32.
# For the device tool (one short run): needs a JAX with CUDA in the environment it runs in, e.g.
#   python3 -m venv .venv-gpu && .venv-gpu/bin/pip install -e . 'jax[cuda12]==0.10.1'   (the pinned version)
# Usage: bash benchmarks/gpu_coupled.sh [python]   (prints the table; RESULTS.md's coupled_step section is rewritten)
set -euo pipefail
cd "$(dirname "$0")"
PY=${1:-../.venv-gpu/bin/python}
"$PY" -c "import jax; print(jax.devices()); assert jax.devices()[0].platform == 'gpu', 'no GPU visible to JAX'"
timeout 540 "$PY" coupled_step.py --sizes 10000 100000 1000000 --steps 200 --no-peers
