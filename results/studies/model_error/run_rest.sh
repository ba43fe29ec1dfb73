#!/bin/sh
# The rest of the model-error study (docs/objective.md), cheapest and most needed rows first.
# Resumable: every finished row is a JSON file in results/studies/model_error/<case>/ and is
# skipped when the phase is run again. One job, one worker: the machine is shared.
# Run from a clean checkout (uncommitted edits of the FE core would reach the runs):
#   nohup sh results/studies/model_error/run_rest.sh >> results/logs/model_error_study3.log 2>&1 &
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
FB=.venv/bin/femubench
REST="linear-shear linear-tension hyperbolic-compression hyperbolic-shear exponent-shear exponent-tension"
ALL="linear-compression $REST hyperbolic-tension exponent-compression"
# the default (bae, 30 mm margin) and its statistics: all nine cases
$FB model-error $ALL --treatments bae --margins 30 --workers 1 --no-figures
# none, one-point, iterated on the full face
$FB model-error $REST --treatments none,one-point,iterated --margins 0 --workers 1 --no-figures
# bae on the full face
$FB model-error $REST --treatments bae --margins 0 --workers 1 --no-figures
# the paper inverse mesh: the linearised bias alone (none, one-point with fine as high fidelity)
$FB model-error $ALL --meshes paper --treatments none,one-point --margins 0,30 --bias-only --workers 1 --no-figures
# the one-point correction at the reference: the floor of paper-based corrections (bias only)
$FB model-error $ALL --treatments hifi-at-reference --margins 0,30 --bias-only --workers 1 --no-figures
# the DIC route (linear-compression): none, and the default
$FB model-error linear-compression --dic --treatments none,bae --margins 30 --workers 1 --no-figures
# the whole coarse grid (adds the 30 mm rows of none, one-point, iterated), then the figures
$FB model-error $ALL --workers 1
