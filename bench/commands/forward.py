"""``femubench forward``: one forward run of the cube test, printed and optionally saved."""

from __future__ import annotations

NAME = "forward"
HELP = (
    "Run the FE model of the cube compression test once (elastic, or a case's Drucker-Prager "
    "material)."
)


def add_arguments(p) -> None:
    from bench.commands._args import (
        MESH_HELP,
        add_mesh_argument,
        output_dir,
        output_file,
        positive_float,
        positive_int,
    )

    p.add_argument(
        "case", nargs="?", help="case name (see `femubench cases`); elastic material when absent"
    )
    add_mesh_argument(p, "coarse", help=f"{MESH_HELP} (default: coarse)")
    p.add_argument(
        "--symmetry",
        default=None,
        metavar="eighth|quarter",
        help="model that is solved: the eighth (z <= 75 mm, mirrored; default where exact, i.e. "
        "NZ even) or the whole-height quarter; same answers, the eighth at half the dofs",
    )
    p.add_argument("--plates", default="friction", choices=["friction", "frictionless"])
    p.add_argument(
        "--displacement",
        type=positive_float,
        default=1.5,
        metavar="MM",
        help="top-plate displacement, mm, > 0 and <= 10%% of the height: 15 (default 1.5)",
    )
    p.add_argument(
        "--snapshots",
        type=positive_int,
        default=10,
        metavar="N",
        help="number of snapshots, >= 1 (default 10)",
    )
    p.add_argument(
        "--param",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="material parameters (MPa, degrees); elastic: E, nu; a case: any of its parameters",
    )
    p.add_argument("--json", metavar="FILE", type=output_file, help="write the response as JSON")
    p.add_argument(
        "--vtu",
        metavar="DIR",
        type=output_dir,
        help="write one VTU file per snapshot and a .pvd collection",
    )


def parse_params(items: list[str]) -> dict[str, float]:
    """``["E=3e4", "nu=0.2"]`` -> ``{"E": 30000.0, "nu": 0.2}``; malformed or non-finite items raise
    ValueError."""
    from bench.commands._args import assignments

    return assignments(items, "--param")


def main(args) -> int:
    import json
    from dataclasses import replace

    from bench.progress import enabled, warn_if_long
    from problems.fe.front_face import measurement_grid
    from problems.fe.mesh import SPECIMEN_MM, SYMMETRIES, check_symmetry, parse_mesh_spec
    from problems.fe.newton import Loading, discretise, run
    from problems.inverse.forward import material_from
    from problems.inverse.plausibility import check_displacement

    check_displacement(args.displacement, SPECIMEN_MM[2], "--displacement")
    spec = parse_mesh_spec(args.mesh)
    if args.symmetry is not None:
        if args.symmetry not in SYMMETRIES:
            raise ValueError(
                f"--symmetry {args.symmetry!r} is unknown; allowed: {', '.join(SYMMETRIES)}"
            )
        named = any(t.strip() in SYMMETRIES for t in str(args.mesh).split(":")[1:])
        if named and spec.symmetry != args.symmetry:
            raise ValueError(
                f"--symmetry {args.symmetry!r} contradicts --mesh {args.mesh!r}; give the model "
                "once"
            )
        spec = replace(spec, symmetry=check_symmetry(args.symmetry, spec.shape, "--symmetry"))
    material = material_from(args.case, parse_params(args.param))
    loading = Loading(args.displacement, args.snapshots, args.plates)
    warn_if_long(NAME, 1, str(spec), what="this forward run")
    mesh = spec.mesh
    disc = discretise(mesh, symmetry=spec.symmetry)
    print(
        f"mesh {args.mesh}: {mesh.n_elements} elements, {mesh.n_dofs} dofs; solved as the "
        f"{spec.symmetry} ({disc.mesh.n_elements} elements, {disc.mesh.n_dofs} dofs); material "
        f"{material!r}"
    )
    response = run(disc, material, loading, progress=disc.mesh.n_elements > 1000 and enabled())
    print(f"{'snapshot':>8} {'top mm':>8} {'reaction kN':>12}")
    for k, (d, f) in enumerate(zip(response.snapshots_mm, response.reaction_kN), 1):
        print(f"{k:8d} {d:8.4f} {f:12.3f}")
    print(
        f"converged: {response.converged} ({response.message}); increments {response.increments}, "
        f"Newton iterations {response.iterations}, cuts {response.cuts}, wall "
        f"{response.wall_s:.2f} s"
    )
    if args.json:
        points = measurement_grid()
        u_h, u_v = response.front_face(points)
        doc = {
            "mesh": mesh.info(),
            "symmetry": spec.symmetry,
            "solved_mesh": disc.mesh.info(),
            "case": args.case,
            "plates": args.plates,
            "snapshots_mm": response.snapshots_mm.tolist(),
            "reaction_kN": response.reaction_kN.tolist(),
            "front_face": {"points": points.tolist(), "u_h": u_h.tolist(), "u_v": u_v.tolist()},
            "converged": response.converged,
            "message": response.message,
            "increments": response.increments,
            "iterations": response.iterations,
            "cuts": response.cuts,
            "wall_s": response.wall_s,
            "timing": response.timing,
        }
        with open(args.json, "w") as fh:
            json.dump(doc, fh, indent=1)
        print(f"wrote {args.json}")
    if args.vtu:
        from problems.fe.vtu import write_vtu

        paths = write_vtu(response, args.vtu)
        print(f"wrote {len(paths)} VTU files to {args.vtu}")
    return 0 if response.converged else 1
