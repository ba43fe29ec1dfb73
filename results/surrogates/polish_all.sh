#!/usr/bin/env bash
# Surrogate search (cma) + FE polish against FE-only LM from random starts, per case as soon as its
# default surrogate is built; resumable (done runs are skipped); it commits nothing: review and commit polish_vs_lm.jsonl yourself.
#   cd <your checkout> && nohup results/surrogates/polish_all.sh > /tmp/polish.log 2>&1 &
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
CASES="${CASES:-linear-compression linear-shear linear-tension hyperbolic-compression hyperbolic-shear hyperbolic-tension exponent-compression exponent-shear exponent-tension}"
STARTS="${STARTS:-2}"
f=results/surrogates/polish_vs_lm.jsonl
for c in $CASES; do
  while [ ! -f "results/surrogates/${c}__coarse/build.json" ]; do sleep 30; done
  echo "=== $c $(date -u +%FT%TZ)"
  .venv/bin/python -m bench.perf.surrogate polish --cases "$c" --starts "$STARTS" --out "$f" || echo "FAILED $c"
done
echo "=== done $(date -u +%FT%TZ)"
