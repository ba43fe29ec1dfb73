#!/usr/bin/env bash
# Posterior study of the nine cases on the default surrogates (consistent tier), one case at a
# time, each as soon as its surrogate is built; resumable (--skip-done); it commits nothing: review and commit the results yourself.
#   cd <your checkout> && nohup results/studies/posterior/run_all.sh > /tmp/posterior.log 2>&1 &
set -u
cd "$(dirname "$0")/../../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
CASES="${CASES:-linear-compression linear-shear linear-tension hyperbolic-compression hyperbolic-shear hyperbolic-tension exponent-compression exponent-shear exponent-tension}"
for c in $CASES; do
  while [ ! -f "results/surrogates/${c}__coarse/build.json" ]; do sleep 30; done
  d="results/studies/posterior/$c"
  if [ -f "$d/summary.json" ]; then echo "skip $c"; continue; fi
  echo "=== $c $(date -u +%FT%TZ)"
  .venv/bin/femubench posterior "$c" --quiet || { echo "FAILED $c"; continue; }
done
echo "=== done $(date -u +%FT%TZ)"
