"""Small helpers shared by the tests (fixtures live in conftest.py)."""

from __future__ import annotations

from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem


def evaluator(model, data, *, mapper=None, cache=True, free_repeats=False, **problem):
    """An :class:`Evaluator` over ``LeastSquaresProblem(model, data, **problem)``."""
    return Evaluator(
        LeastSquaresProblem(model, data, **problem),
        mapper=mapper,
        cache=cache,
        free_repeats=free_repeats,
    )


def material(form: str, hardening: str, **overrides):
    """A Drucker-Prager material of ``form``/``hardening`` at its typical parameters
    (+ overrides)."""
    from problems.materials.drucker_prager import make_material
    from problems.materials.verification import typical_parameters

    return make_material(form, hardening, {**typical_parameters(form, hardening), **overrides})


#: the nine (form, hardening) variants of the extended Drucker-Prager family
VARIANTS = [
    (f, h)
    for f in ("linear", "hyperbolic", "exponent")
    for h in ("compression", "shear", "tension")
]


def assert_shipped_calibration_is_of(out, data, case, settings) -> bool:
    """A shipped ``femubench calibrate`` folder ``out`` belongs to the imported ``data``: keyed by
    its hash when this machine's arithmetic imports the example bit for bit as the machine that
    made it did (then rerunning the command resumes: True); otherwise (another CPU or BLAS
    changes the last digits of the import, the hash with them: False) its ``case`` variant's
    stored chi2 is the objective at its identified parameters on today's import within 1e-9
    relative (measured 3e-15 and 6e-15 between the machine that made them and a Zen 3 one): the
    same calibration, up to this machine's last digits."""
    import json

    import numpy as np

    from bench import calibration as cal

    report = json.loads((out / "report.json").read_text())
    done = json.loads((out / "variants" / f"{case.name}.json").read_text())
    if report["data_hash"] == data.hash:
        assert done["key"] == cal.variant_key(data, case, settings)
        return True
    assert done["correction"] == "none"
    ev = cal.objective_for(data, case, settings.mesh)
    chi2 = ev.evaluate(ev.to_scaled(np.array(done["x"]))).cost
    assert abs(chi2 - done["chi2"]) <= 1e-9 * done["chi2"], (chi2, done["chi2"])
    return False
