"""The plate test in OpenSees (``bbarBrick`` / ``stdBrick`` + ``nDMaterial DruckerPrager``) on a
femubench mesh, with the solution strategies tried in turn, and a digest of OpenSees's log.

Units: mm, N (OpenSees side), kN (whole-specimen force), MPa.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench.crosscheck.loader import captured_output, load_opensees
from bench.crosscheck.mapping import OPENSEES_ARGS


@dataclass(frozen=True)
class Strategy:
    """OpenSees solution settings for one attempt."""

    name: str
    substeps: int = 1  # analysis steps per snapshot
    test: tuple = ("NormUnbalance", 1e-4, 25)  # N: ~1e-9 of the plate force
    algorithm: tuple = ("Newton",)
    system: str = "UmfPack"
    constraints: tuple = ("Transformation",)


BASELINE = Strategy("Newton, 10 steps, NormUnbalance 1e-4 N")
#: the usual cures, tried in this order when the baseline fails: first at the same load steps,
#: then with smaller steps
CURES = (
    Strategy("Newton, NormDispIncr 1e-10 mm", test=("NormDispIncr", 1e-10, 50)),
    Strategy("KrylovNewton", algorithm=("KrylovNewton",), test=("NormUnbalance", 1e-4, 100)),
    Strategy(
        "NewtonLineSearch",
        algorithm=("NewtonLineSearch", "-type", "Bisection"),
        test=("NormUnbalance", 1e-4, 100),
    ),
    Strategy("ModifiedNewton", algorithm=("ModifiedNewton",), test=("NormUnbalance", 1e-4, 200)),
    Strategy("Newton, Penalty constraint handler", constraints=("Penalty", 1e12, 1e12)),
    Strategy("Newton, 2x smaller steps", substeps=2),
    Strategy("Newton, 5x smaller steps", substeps=5),
    Strategy("Newton, 10x smaller steps", substeps=10),
)


@dataclass
class OpenSeesRun:
    """One OpenSees attempt at the plate test: the converged snapshots and how the iteration
    went."""

    strategy: str
    element: str
    converged: bool
    snapshots_mm: np.ndarray
    # whole-specimen force for the quarter cube (x4), kN, compression > 0
    reaction_kN: np.ndarray
    force_N: np.ndarray  # force on the modelled body, N
    displacements: np.ndarray  # (N, n_nodes, 3) mm
    stress: np.ndarray  # (N, n_elements, 6) element mean, femubench Voigt order
    wall_s: float
    failure: dict = field(default_factory=dict)
    log: str = ""
    step_iterations: list = field(default_factory=list)  # Newton iterations of each analysis step
    step_norms: list = field(default_factory=list)  # test norms of each step's iterations


# OpenSees brick stress output sigma11, sigma22, sigma33, sigma12, sigma23,
# sigma13 -> [xx, yy, zz, yz, xz, xy]
OS_TO_VOIGT = [0, 1, 2, 4, 5, 3]


def opensees_box(
    mesh,
    osp: dict,
    delta: float,
    steps: int,
    plates: str,
    *,
    element: str = "bbarBrick",
    strategy: Strategy = BASELINE,
    quarter: bool = True,
    log_dir: Path | None = None,
) -> OpenSeesRun:
    """The plate test of ``mesh`` in OpenSees with the same boundary conditions as
    :class:`problems.fe.BoundaryConditions`: u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 at the
    bottom, u_z = -delta (sp constraint, linear in the load factor) at the top, and with friction
    plates u_x = u_y = 0 at bottom and top. Node tag = femubench node index + 1."""
    ops = load_opensees()
    nn = mesh.n_nodes
    fixed = np.zeros((nn, 3), int)
    fixed[mesh.face("x0"), 0] = 1
    fixed[mesh.face("y0"), 1] = 1
    fixed[mesh.face("z0"), 2] = 1
    if plates == "friction":
        for face in ("z0", "z1"):
            fixed[mesh.face(face), :2] = 1
    top = mesh.face("z1")
    log_path = Path(tempfile.mkstemp(prefix="opensees_", suffix=".log", dir=log_dir)[1])
    t0 = time.perf_counter()
    out_u, out_s, out_f, out_d = [], [], [], []
    failure: dict = {}
    step_iterations: list[int] = []
    step_norms: list[list[float]] = []
    with captured_output(log_path):
        ops.wipe()
        ops.model("basic", "-ndm", 3, "-ndf", 3)
        for i, (x, y, z) in enumerate(mesh.nodes):
            ops.node(i + 1, float(x), float(y), float(z))
            if fixed[i].any():
                ops.fix(i + 1, *map(int, fixed[i]))
        ops.nDMaterial("DruckerPrager", 1, *(float(osp[k]) for k in OPENSEES_ARGS))
        for e, conn in enumerate(mesh.elements):
            ops.element(element, e + 1, *map(int, conn + 1), 1)
        ops.timeSeries("Linear", 1)
        ops.pattern("Plain", 1, 1)
        for n in top:
            ops.sp(int(n) + 1, 3, -float(delta))
        ops.constraints(*strategy.constraints)
        ops.numberer("RCM")
        ops.system(strategy.system)
        ops.test(*strategy.test)
        ops.algorithm(*strategy.algorithm)
        ops.integrator("LoadControl", 1.0 / (steps * strategy.substeps))
        ops.analysis("Static")
        for k in range(1, steps + 1):
            for j in range(strategy.substeps):
                ok = ops.analyze(1)
                step_iterations.append(int(ops.testIter()))
                step_norms.append([float(v) for v in ops.testNorm()[: step_iterations[-1]]])
                if ok < 0:
                    norms = list(ops.testNorm())
                    failure = {
                        "snapshot": k,
                        "substep": j + 1,
                        "top_mm_from": float(
                            delta * ((k - 1) * strategy.substeps + j) / (steps * strategy.substeps)
                        ),
                        "top_mm_to": float(
                            delta
                            * ((k - 1) * strategy.substeps + j + 1)
                            / (steps * strategy.substeps)
                        ),
                        "iterations": int(ops.testIter()),
                        "last_norms": [float(v) for v in norms[-6:]],
                        "first_norms": [float(v) for v in norms[:6]],
                    }
                    break
            if failure:
                break
            ops.reactions()
            u = np.array([ops.nodeDisp(i + 1) for i in range(nn)])
            stress = np.array(
                [
                    np.reshape(ops.eleResponse(e + 1, "stresses"), (8, 6)).mean(axis=0)
                    for e in range(mesh.n_elements)
                ]
            )[:, OS_TO_VOIGT]
            out_u.append(u)
            out_s.append(stress)
            out_f.append(-sum(ops.nodeReaction(int(n) + 1, 3) for n in top))
            out_d.append(-float(np.mean(u[top, 2])))
        ops.wipe()
    wall = time.perf_counter() - t0
    log = log_path.read_text(errors="replace")
    log_path.unlink()
    f = np.array(out_f)
    return OpenSeesRun(
        strategy.name,
        element,
        not failure,
        np.array(out_d),
        (4.0 if quarter else 1.0) * f / 1000.0,
        f,
        np.array(out_u).reshape(-1, nn, 3),
        np.array(out_s).reshape(-1, mesh.n_elements, 6),
        wall,
        failure,
        log,
        step_iterations,
        step_norms,
    )


def summarise_log(log: str, limit: int = 6) -> dict:
    """Counts of OpenSees's messages and the first distinct lines (the log can be very long)."""
    lines = [ln.strip() for ln in log.splitlines() if ln.strip()]
    ignore = ("DruckerPrager nDmaterial", "Process 0 Terminating")
    lines = [ln for ln in lines if not ln.startswith(ignore)]
    distinct: list[str] = []
    for ln in lines:
        key = ln[:80]
        if key not in distinct and len(distinct) < limit:
            distinct.append(key)
    return {
        "lines": len(lines),
        "first": distinct,
        "jact_messages": sum("Jact" in ln for ln in lines),
        "normcep_messages": sum("NormCep" in ln for ln in lines),
        "failed_messages": sum("failed" in ln.lower() for ln in lines),
    }
