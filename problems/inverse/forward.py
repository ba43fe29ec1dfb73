"""The FE model of the cube test as a forward model of the objective: parameters -> measurements.

The measurement vector of one run is laid out by :mod:`problems.inverse.layout`. With
``jacobian=True`` the same run also gives the exact Jacobian dU/dx by direct differentiation
(problems/fe/ddm.py), chained from the material's parameters to the identified ones.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import ClassVar

import numpy as np

from problems.fe.front_face import front_face_operator, measurement_grid
from problems.fe.mesh import SPECIMEN_MM, MeshSpec, parse_mesh_spec, quarter_size
from problems.fe.newton import Discretisation, Loading, NewtonSettings, discretise, run
from problems.inverse import layout
from problems.inverse.case import Case
from problems.inverse.cases import get_case
from problems.materials import LinearElastic

#: tighter than the solver defaults so that finite-difference Jacobians are clean
FORWARD_SETTINGS = NewtonSettings(rtol_force=1e-10, rtol_displacement=1e-10)

#: relative finite-difference steps of the FE model by scheme (its values carry the Newton
#: tolerance's noise, ~1e-10, not machine precision). Forward: the truncation error (~h) and the
#: noise (~1e-10 / h) balance near 1e-5..1e-6; 1e-6 keeps columns within ~1e-5 of the exact ones.
#: Central: truncation ~h^2, so 1e-4 leaves ~1e-8 (measured on coarse against the DDM Jacobian:
#: clean from 1e-3 down to 1e-5; see docs/fe_model.md). The evaluator uses them for this model.
FD_REL_STEP = {"forward": 1e-6, "central": 1e-4}

#: nominal price of ``model(x, jacobian=True)`` (response + exact Jacobian, 6 parameters) in plain
#: forward runs, per mesh preset: the largest ratio measured by ``bench/perf/jacobian.py`` (wall
#: or CPU time; coarse: 1.68 over the nine cases, paper: 1.97 on two; docs/fe_model.md "Cost"),
#: rounded up to a tenth. The evaluator charges it when budgets are counted in
#: forward-equivalents; other meshes (not measured) get the largest value
JACOBIAN_COST = {"coarse": 1.7, "paper": 2.0}


def discretisation(mesh: str, specimen_mm=SPECIMEN_MM) -> Discretisation:
    """Discretisation of a mesh spec (``coarse``, ``coarse:quarter``,
    ``NX,NY,NZ[:eighth|:quarter]``) of the quarter model of a rectangular specimen of (x, y, z)
    extents ``specimen_mm`` (mm; default the 150 mm cube), built once per process (workers reuse
    it across runs). Presets and even NZ solve the eighth model by default (same answers as the
    quarter, see docs/fe_model.md)."""
    return _discretisation(str(parse_mesh_spec(mesh)), quarter_size(specimen_mm))


@lru_cache(maxsize=4)
def _discretisation(canonical: str, size_mm: tuple[float, float, float]) -> Discretisation:
    spec = parse_mesh_spec(canonical)
    return discretise(spec.build(size_mm), symmetry=spec.symmetry)


#: the kinds of FE run this process has warmed up (:meth:`FEForwardModel.warm_up`): (element,
#: symmetry, plates, material form, hardening, sensitivity parameters or None)
_WARMED: set[tuple] = set()


def case_material(case: Case, x):
    """The Drucker-Prager material of ``case`` at active parameters ``x`` (physical units)."""
    from problems.materials.drucker_prager import make_material

    return make_material(case.form, case.hardening, case.material_parameters(x))


def material_from(case_name: str | None, overrides: dict[str, float]):
    """Material for the CLI: elastic (E, nu) without a case, else the case's at
    reference + overrides."""
    if case_name is None:
        unknown = set(overrides) - {"E", "nu"}
        if unknown:
            raise ValueError(
                f"--param {sorted(unknown)} unknown for the elastic material; allowed: E, nu"
            )
        return LinearElastic(**overrides)
    case = get_case(case_name)
    allowed = set(case.names) | set(case.fixed)
    unknown = set(overrides) - allowed
    if unknown:
        raise ValueError(
            f"--param {sorted(unknown)} unknown for case {case.name}; allowed: "
            f"{', '.join(sorted(allowed))}"
        )
    from problems.materials.drucker_prager import make_material

    x = np.array([overrides.get(n, r) for n, r in zip(case.names, case.reference)], float)
    fixed = {k: v for k, v in overrides.items() if k in case.fixed}
    return make_material(case.form, case.hardening, {**case.material_parameters(x), **fixed})


@dataclass(frozen=True, eq=False)
class FEForwardModel:
    """Forward model of the objective backed by the FE cube test (picklable for Dask workers).

    case     : the identification case (which parameters are active)
    mesh     : mesh spec (``coarse``, ``paper``, ``fine`` or ``NX,NY,NZ``, optionally ``:eighth``
               or ``:quarter``; by default the eighth model where it is exact)
    loading  : plate displacement, snapshots and plate condition
    points   : (m, 2) front-face measurement points (y, z), mm
    specimen_mm : (x, y, z) extents of the whole specimen, mm (the camera sees the face
               x = specimen_mm[0] / 2 of the quarter model; default the 150 mm cube)

    ``model(x, jacobian=True)`` returns the exact Jacobian dU/dx (m, n) too: rows the measurement
    vector (mm per unit of x for the displacements, kN per unit for the force), columns the
    identified parameters in physical units, from one run with sensitivities; it costs
    ``jacobian_cost`` plain runs (nominal, :data:`JACOBIAN_COST`).
    """

    provides_jacobian: ClassVar[bool] = True
    fd_rel_step: ClassVar[dict] = FD_REL_STEP

    case: Case
    mesh: str = "coarse"
    loading: Loading = Loading()
    points: np.ndarray = field(default_factory=measurement_grid)
    settings: NewtonSettings = FORWARD_SETTINGS
    specimen_mm: tuple[float, float, float] = SPECIMEN_MM

    @property
    def names(self) -> tuple[str, ...]:
        return self.case.names

    @property
    def jacobian_cost(self) -> float:
        """Nominal forward-equivalents of one response + exact Jacobian on this mesh."""
        base = str(self.mesh).partition(":")[0]
        return JACOBIAN_COST.get(base, max(JACOBIAN_COST.values()))

    def check(self, x) -> str | None:
        """None when ``x`` defines a well-posed material, else the reason (no FE run)."""
        from problems.materials.drucker_prager import validate_parameters

        try:
            validate_parameters(
                self.case.form, self.case.hardening, self.case.material_parameters(x)
            )
        except ValueError as exc:
            return str(exc)
        return None

    def response(self, x, *, progress: bool = False, sensitivities=False):
        """The full FE :class:`~problems.fe.Response` at ``x`` (with ``sensitivities``: see
        :func:`problems.fe.newton.run`; names are the material's parameters)."""
        return run(
            discretisation(self.mesh, self.specimen_mm),
            case_material(self.case, x),
            self.loading,
            self.settings,
            progress=progress,
            sensitivities=sensitivities,
        )

    def material_chain(self, x) -> tuple[tuple[str, ...], np.ndarray]:
        """The material parameters the identified ones move, and d(those)/dx (P', n): the rows of
        ``case.material_jacobian`` that are not zero (fixed constants such as nu are dropped)."""
        material = case_material(self.case, x)
        chain = self.case.material_jacobian(x, material.parameter_names)
        keep = np.flatnonzero(np.any(chain != 0.0, axis=1))
        return tuple(material.parameter_names[i] for i in keep), chain[keep]

    def __call__(self, x, jacobian: bool = False):
        return self.run_with_response(x, jacobian)[0]

    def run_with_response(self, x, jacobian: bool = False):
        """``(self(x, jacobian), response)``: the :class:`ForwardResult` and the FE
        :class:`~problems.fe.Response` it was taken from (None when the material was refused)."""
        from problems.inverse.protocol import ForwardResult

        self.warm_up(x, jacobian)
        t0 = time.perf_counter()
        try:
            if jacobian:
                names, chain = self.material_chain(x)
                resp = self.response(x, sensitivities=names)
            else:
                resp = self.response(x)
        except ValueError as exc:  # invalid material parameters slipped past check()
            return ForwardResult(False, None, str(exc), time.perf_counter() - t0), None
        if not resp.converged:
            return ForwardResult(False, None, resp.message, time.perf_counter() - t0), resp
        W = front_face_operator(resp.mesh, self.points)  # as Response.front_face
        u = resp.displacements
        values = layout.stack(u[:, :, 1] @ W.T, u[:, :, 2] @ W.T, resp.reaction_kN)
        J, message, plain_s = None, "", None
        if jacobian:
            t1 = time.perf_counter()
            J = self.jacobian_from(resp, chain, W)
            if J is None:
                message = f"no exact Jacobian: {resp.sensitivities.message}"
            # the Newton run is bit for bit a plain run: its time without the sensitivities',
            # plus the converged tangents its predictors took over from them
            sens = resp.sensitivities
            plain_s = t1 - t0 - sens.wall_s + sens.timing.get("reused_tangent_s", 0.0)
        wall = time.perf_counter() - t0
        return ForwardResult(True, values, message, wall, J, plain_s), resp

    def warm_up(self, x, jacobian: bool = False) -> bool:
        """Compile the numba kernels of this kind of run once per process, untimed: numba's JIT
        (seconds; tens with a cold cache) is a one-off of the process, not a cost of the method,
        and would otherwise be charged to the first evaluation's wall time (the measured
        forward-equivalents). Runs ``x`` on the smallest mesh of the same element and symmetry
        (1 x 1 x 2, two snapshots), same material, plates, settings and sensitivities, on its
        own discretisation: nothing the real runs use is touched. Also builds this model's
        discretisation. True when it ran (first call of its kind), False otherwise."""
        spec = parse_mesh_spec(self.mesh)
        discretisation(self.mesh, self.specimen_mm)
        try:
            names, chain = self.material_chain(x) if jacobian else (None, None)
            key = (
                spec.element,
                spec.symmetry,
                self.loading.plates,
                self.case.form,
                self.case.hardening,
                names,
            )
            if key in _WARMED:
                return False
            tiny = MeshSpec((1, 1, 2), spec.symmetry, element=spec.element)
            disc = discretise(tiny.build(quarter_size(self.specimen_mm)), symmetry=tiny.symmetry)
            loading = replace(self.loading, snapshots=min(2, self.loading.snapshots))
            resp = run(
                disc,
                case_material(self.case, x),
                loading,
                self.settings,
                sensitivities=names or False,
            )
        except Exception:  # never changes a run's outcome: the real run reports what failed
            return False
        if resp.converged:
            W = front_face_operator(resp.mesh, self.points)
            if jacobian:
                self.jacobian_from(resp, chain, W)
        _WARMED.add(key)
        return True

    def jacobian_from(self, resp, chain, operator=None) -> np.ndarray | None:
        """dU/dx (m, n) in the layout of the measurement vector from a response with sensitivities
        (columns ``material_chain(x)[0]``) and ``chain`` = d(material params)/dx; None when its
        sensitivities failed. ``operator``: the front-face interpolation operator, if at hand."""
        sens = resp.sensitivities
        if sens is None or not sens.ok:
            return None
        du_h, du_v = sens.front_face(self.points, resp.mesh, operator)
        k = len(sens.parameter_names)
        Jp = np.concatenate([du_h.reshape(-1, k), du_v.reshape(-1, k), sens.reaction_kN])
        return Jp @ chain
