"""Surrogate forward models: POD of FE snapshots + RBF or Gaussian-process regression, built once,
stored, validated on fresh hold-out runs and used wherever a forward model is
(see docs/surrogate.md).

design.py      training designs (Latin hypercube / Sobol, optional local enrichment)
training.py    counted runs of a model over a design, through a mapper, in batches
pod.py         POD of the sigma-scaled snapshots, truncated in units of the noise
regression.py  RBF and GP regression of the POD coefficients, with exact gradients
model.py       :class:`SurrogateModel`, the forward-model protocol (values, Jacobian,
               extrapolation flag)
validation.py  hold-out errors in sigma and in um / kN, cost of one evaluation
build.py       design -> runs -> POD -> regression (selected) -> validation
store.py       npz + JSON with a content hash; name look-up
"""

from problems.surrogate.build import (
    SurrogateSettings,
    build_case_surrogate,
    build_surrogate,
    fit_surrogate,
)
from problems.surrogate.model import SurrogateModel
from problems.surrogate.store import default_name, load, save

__all__ = [
    "SurrogateModel",
    "SurrogateSettings",
    "build_surrogate",
    "build_case_surrogate",
    "fit_surrogate",
    "load",
    "save",
    "default_name",
]
