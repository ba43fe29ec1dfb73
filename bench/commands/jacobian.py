"""``femubench jacobian``: the Jacobian dU/dx of the measurement vector of one case at one point.

``--method analytic`` (default) is one FE run with exact sensitivities by direct differentiation
(problems/fe/ddm.py); ``forward`` (n + 1 runs) and ``central`` (2 n + 1 runs, the base run
being the response) are finite differences of plain runs for comparison, with the FE model's
relative steps (problems.inverse.forward.FD_REL_STEP, h_j = step * |x_j|). Every method's wall
time (response included) is reported against one plain forward run of the same point timed in
the same command.
"""

from __future__ import annotations

NAME = "jacobian"
HELP = (
    "Jacobian dU/dx of the measurement vector (front-face u_h, u_v, plate force) of a case: "
    "exact sensitivities from one FE run (DDM) or finite differences, and its cost in forward "
    "runs."
)

METHODS = ("analytic", "forward", "central")


def _steps() -> dict[str, float]:
    """The FE model's relative finite-difference steps by scheme
    (:data:`problems.inverse.forward.FD_REL_STEP`; imported when used: the FE stack is heavy)."""
    from problems.inverse.forward import FD_REL_STEP

    return FD_REL_STEP


#: a tiny mesh run once before the timings, so that loading the compiled (numba) kernels is not
#: charged to the first timed run
WARM_UP_MESH = "1,1,2"


def add_arguments(p) -> None:
    from bench.commands._args import MESH_HELP, add_mesh_argument, output_file

    p.add_argument("case", help="FE case name (see `femubench cases`)")
    add_mesh_argument(p, "coarse", help=f"{MESH_HELP} (default: coarse)")
    p.add_argument(
        "--param",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="identified parameters (MPa, degrees, -) to change from the case's reference",
    )
    p.add_argument(
        "--method",
        choices=METHODS,
        default="analytic",
        help="analytic: one run with exact sensitivities (DDM); forward: n + 1 runs, "
        "central: 2 n + 1 runs, with the FE model's relative steps (problems.inverse.forward."
        "FD_REL_STEP) (default: analytic)",
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        type=output_file,
        help="write names, x, jacobian (rows: u_h snapshot-major, u_v, reaction_kN; "
        "columns: names), wall_s, forward_wall_s",
    )


def point(case, overrides: dict[str, float]):
    """The physical point: the case's reference with ``overrides`` of identified parameters."""
    import numpy as np

    unknown = sorted(set(overrides) - set(case.names))
    if unknown:
        raise ValueError(
            f"--param {unknown} unknown for case {case.name}; allowed: {', '.join(case.names)}"
        )
    return np.array([overrides.get(n, r) for n, r in zip(case.names, case.reference)], float)


def finite_difference(model, x, base, scheme: str):
    """(m, n) finite-difference Jacobian of ``model`` at ``x`` (``base``: its values), and the runs
    it made; ValueError naming the column when a perturbed run fails."""
    import numpy as np

    step = _steps()[scheme]
    cols, runs = [], 0
    for j, name in enumerate(model.names):
        h = step * max(abs(x[j]), 1e-8)
        values = []
        for sign in (1.0,) if scheme == "forward" else (1.0, -1.0):
            xs = x.copy()
            xs[j] += sign * h
            res = model(xs)
            runs += 1
            if not res.ok:
                raise ValueError(
                    f"the run at {name} {'+' if sign > 0 else '-'} {h:.3g} failed: {res.message}"
                )
            values.append(res.values)
        if scheme == "forward":
            cols.append((values[0] - base) / h)
        else:
            cols.append((values[0] - values[1]) / (2.0 * h))
    return np.column_stack(cols), runs


def main(args) -> int:
    import json
    import time

    import numpy as np

    from bench.commands._args import assignments
    from problems.fe.mesh import parse_mesh_spec
    from problems.inverse.cases import get_case
    from problems.inverse.forward import FEForwardModel, discretisation

    case = get_case(args.case)
    if case.is_analytic:
        raise ValueError(
            f"case {case.name} is analytic; femubench jacobian needs an FE case "
            "(see `femubench cases`)"
        )
    spec = parse_mesh_spec(args.mesh)
    x = point(case, assignments(args.param, "--param"))
    model = FEForwardModel(case, args.mesh)
    why = model.check(x)
    if why:
        raise ValueError(f"x is not a well-posed material: {why}")
    discretisation(args.mesh)  # built once, outside the timings, like the compiled kernels:
    FEForwardModel(case, WARM_UP_MESH)(x, jacobian=args.method == "analytic")
    t = time.perf_counter()
    plain = model(x)
    forward_wall = time.perf_counter() - t
    if not plain.ok:
        print(f"femubench jacobian: the forward run failed: {plain.message}")
        return 1
    t = time.perf_counter()
    if args.method == "analytic":
        res = model(x, jacobian=True)
        if not res.ok or res.jacobian is None:
            print(f"femubench jacobian: the run with sensitivities failed: {res.message}")
            return 1
        J, runs = res.jacobian, 1
    else:  # the response (the base run) is part of the cost, as in the analytic run
        base = model(x)
        J, runs = finite_difference(model, x, base.values, args.method)
        runs += 1
    wall = time.perf_counter() - t
    n_s, n_p = model.loading.snapshots, len(model.points)
    disp = slice(0, 2 * n_s * n_p)
    print(
        f"case {case.name}, mesh {args.mesh} ({spec.symmetry}), method {args.method}: "
        f"J is {J.shape[0]} x {J.shape[1]} (u_h, u_v: {n_s} snapshots x {n_p} points, then "
        f"{n_s} forces)"
    )
    print(f"{'parameter':10} {'x':>12} {'|dU_disp/dx| mm':>16} {'dF_end/dx kN':>14}")
    for j, name in enumerate(case.names):
        print(f"{name:10} {x[j]:12.6g} {np.linalg.norm(J[disp, j]):16.6g} {J[-1, j]:14.6g}")
    ratio = wall / forward_wall
    # the nominal price (problems/inverse/evaluator.py): the response + n or 2n perturbed runs,
    # or the model's declared jacobian_cost for the run with sensitivities
    nominal = runs + 1 if args.method != "analytic" else model.jacobian_cost
    print(
        f"cost: {wall:.3f} s ({runs} run{'s' if runs > 1 else ''}, response included) = "
        f"{ratio:.2f} x one forward run ({forward_wall:.3f} s); charged {nominal:g} "
        "forward-equivalents in budgets counted in them"
    )
    if args.json:
        doc = {
            "case": case.name,
            "mesh": args.mesh,
            "symmetry": spec.symmetry,
            "method": args.method,
            "names": list(case.names),
            "x": x.tolist(),
            "jacobian": J.tolist(),
            "rows": {"u_h": [n_s, n_p], "u_v": [n_s, n_p], "reaction_kN": n_s},
            "rel_step": _steps().get(args.method),
            "runs": runs,
            "wall_s": wall,
            "forward_wall_s": forward_wall,
            "cost_ratio": ratio,
            "nominal_forward_equivalents": nominal,
        }
        with open(args.json, "w") as fh:
            json.dump(doc, fh, indent=1)
        print(f"wrote {args.json}")
    return 0
