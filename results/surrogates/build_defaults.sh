#!/usr/bin/env bash
# Build the nine default surrogates (coarse mesh, shipped data points and sigma), one at a time
# with 2 workers; resumable: a case whose folder already holds surrogate.json and build.json is
# skipped. femubench surrogate writes surrogate.npz, surrogate.json and build.json into --out as
# one unit. The script commits nothing: review and commit the new folders yourself.
#   cd <your checkout> && nohup results/surrogates/build_defaults.sh > /tmp/build_defaults.log 2>&1 &
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
CASES="${CASES:-linear-compression linear-shear linear-tension hyperbolic-compression hyperbolic-shear hyperbolic-tension exponent-compression exponent-shear exponent-tension}"
for c in $CASES; do
  d="results/surrogates/${c}__coarse"
  if [ -f "$d/surrogate.json" ] && [ -f "$d/build.json" ]; then echo "skip $c"; continue; fi
  echo "=== $c $(date -u +%FT%TZ)"
  rm -rf "$d.tmp"
  if .venv/bin/femubench surrogate "$c" --mesh coarse --samples 300 --local 40 --local-scale 0.1 \
      --holdout 50 --regression gp --gp-restarts 1 --workers 2 --quiet \
      --out "$d.tmp"; then
    rm -rf "$d" && mv "$d.tmp" "$d"
  else
    echo "FAILED $c"
  fi
done
echo "=== done $(date -u +%FT%TZ)"
