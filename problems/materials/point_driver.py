"""Material-point driver: one constitutive point taken along a standard test path.

For calibration engineers: it shows what a parameter set does in the tests the hardening is
defined by, without any FE. The paths (``strain`` is a magnitude, the path sets the sign)::

    uniaxial-compression  eps_xx = -strain * k/N, the five other stress components held at 0
    uniaxial-tension      eps_xx = +strain * k/N, the five other stress components held at 0
    shear                 gamma_xy = +strain * k/N (engineering), the other stresses held at 0
                          (pure shear *stress*, as in the shear hardening test; dilatancy shows
                          as free normal strains)
    hydrostatic           eps_xx = eps_yy = eps_zz = +strain * k/N, no shear: hydrostatic
                          tension, the only hydrostatic path on which these cap-less surfaces
                          yield (hydrostatic compression stays elastic)

Stress-free components are found by a Newton iteration on their strains with the material's
consistent tangent; a step that does not converge (or whose local return fails) is bisected.

Output columns: ``step, eps_axial, sig_axial, p, q, eqps`` with eps_axial / sig_axial the
controlled strain and its stress (xx for the uniaxial and hydrostatic paths, gamma_xy and
tau_xy for shear), p = -tr(sigma)/3 and q the von Mises stress (MPa), eqps the equivalent plastic
strain (0 for materials without one).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass

import numpy as np

from problems.materials.base import Material
from problems.materials.invariants import mises, pressure

PATHS = ("uniaxial-compression", "uniaxial-tension", "shear", "hydrostatic")
COLUMNS = ("step", "eps_axial", "sig_axial", "p", "q", "eqps")

# path: (strain direction (6,), controlled Voigt component, stress-free components)
_PATH_SPECS = {
    "uniaxial-compression": (-np.eye(6)[0], 0, (1, 2, 3, 4, 5)),
    "uniaxial-tension": (np.eye(6)[0], 0, (1, 2, 3, 4, 5)),
    "shear": (np.eye(6)[5], 5, (0, 1, 2, 3, 4)),
    "hydrostatic": (np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0]), 0, ()),
}


@dataclass(frozen=True)
class MaterialPointResult:
    """The table of a material-point run (one row per step) and the full histories.

    table  : (steps, 6) with the columns :data:`COLUMNS`
    strain : (steps, 6) total strain (engineering shear), stress : (steps, 6) MPa,
    state  : (steps, n_state) history variables
    """

    path: str
    table: np.ndarray
    strain: np.ndarray
    stress: np.ndarray
    state: np.ndarray
    columns: tuple[str, ...] = COLUMNS

    def column(self, name: str) -> np.ndarray:
        """One column of the table by name."""
        return self.table[:, self.columns.index(name)]

    def format(self) -> str:
        """Fixed-width text table with a header line."""
        head = f"{'step':>6} " + " ".join(f"{c:>14}" for c in self.columns[1:])
        rows = [f"{int(r[0]):>6d} " + " ".join(f"{v:>14.6e}" for v in r[1:]) for r in self.table]
        return "\n".join([head, *rows])

    def write_csv(self, path) -> None:
        """CSV with a header row; full double precision."""
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(self.columns)
            for r in self.table:
                w.writerow([int(r[0]), *(repr(float(v)) for v in r[1:])])


def run_material_point(
    material: Material,
    path: str,
    strain: float,
    steps: int,
    *,
    tol: float = 1e-10,
    max_iter: int = 30,
    max_cuts: int = 12,
) -> MaterialPointResult:
    """Drive ``material`` along ``path`` to the strain magnitude ``strain`` in ``steps`` equal
    steps.

    tol: stress-free components are converged to ``tol * max(1 MPa, max |sigma|)``.
    Raises ValueError for bad input and RuntimeError if a step cannot be completed even after
    ``max_cuts`` bisections.
    """
    if path not in _PATH_SPECS:
        raise ValueError(f"path {path!r} is unknown; allowed: {', '.join(PATHS)}")
    strain = float(strain)
    if not (np.isfinite(strain) and strain > 0.0):
        raise ValueError(
            f"strain = {strain!r} must be a positive magnitude (the path sets the sign)"
        )
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps = {steps!r} must be a positive integer")
    steps = int(steps)
    direction, ctrl, free = _PATH_SPECS[path]
    free = np.array(free, dtype=int)

    eps = np.zeros(6)
    sig = np.zeros(6)
    state = material.initial_state(1)[0]
    tangent = None
    rows, eps_hist, sig_hist, state_hist = [], [], [], []
    d_eps = direction * strain / steps
    for k in range(1, steps + 1):
        eps, sig, state, tangent = _advance(
            material, eps, sig, state, tangent, d_eps, free, tol, max_iter, max_cuts
        )
        eqps = state[material.state_names.index("eqps")] if "eqps" in material.state_names else 0.0
        # + 0.0 turns the -0.0 of a vanishing pressure into 0.0 for the printed table
        rows.append(
            (k, eps[ctrl], sig[ctrl], pressure(sig[None])[0] + 0.0, mises(sig[None])[0], eqps)
        )
        eps_hist.append(eps.copy())
        sig_hist.append(sig.copy())
        state_hist.append(state.copy())
    return MaterialPointResult(
        path,
        np.array(rows, float),
        np.array(eps_hist),
        np.array(sig_hist),
        np.array(state_hist).reshape(steps, -1),
    )


def _advance(material, eps, sig, state, tangent, d_eps, free, tol, max_iter, cuts_left):
    """One step of the prescribed strain ``d_eps`` (free components found); bisects on failure."""
    result = _try_step(material, sig, state, tangent, d_eps, free, tol, max_iter)
    if result is not None:
        de, sig_new, state_new, tan_new = result
        return eps + de, sig_new, state_new, tan_new
    if cuts_left == 0:
        raise RuntimeError(
            "material point: a step did not converge even after bisection; "
            "reduce the strain or increase the number of steps"
        )
    half = 0.5 * d_eps
    eps, sig, state, tangent = _advance(
        material, eps, sig, state, tangent, half, free, tol, max_iter, cuts_left - 1
    )
    return _advance(material, eps, sig, state, tangent, half, free, tol, max_iter, cuts_left - 1)


def _try_step(material, sig, state, tangent, d_eps, free, tol, max_iter):
    """Newton on the free strain components so that their stresses vanish; None on failure."""
    de = d_eps.copy()
    if free.size:
        T = (
            tangent
            if tangent is not None
            else material.update(np.zeros((1, 6)), sig[None], state[None]).tangent[0]
        )
        fixed = np.setdiff1d(np.arange(6), free)
        # predictor: the free strains that keep the current tangent's free stresses unchanged
        de[free] = -np.linalg.solve(T[np.ix_(free, free)], T[np.ix_(free, fixed)] @ d_eps[fixed])
    for _ in range(max_iter):
        up = material.update(de[None], sig[None], state[None])
        if not up.ok[0] or not np.all(np.isfinite(up.stress)):
            return None
        s_new = up.stress[0]
        if free.size == 0:
            return de, s_new, up.state[0], up.tangent[0]
        r = s_new[free]
        if np.abs(r).max() <= tol * max(1.0, np.abs(s_new).max()):
            return de, s_new, up.state[0], up.tangent[0]
        try:
            de[free] -= np.linalg.solve(up.tangent[0][np.ix_(free, free)], r)
        except np.linalg.LinAlgError:
            return None
    return None
