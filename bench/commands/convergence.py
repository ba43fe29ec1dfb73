"""``femubench convergence CASE|all``: mesh convergence of the forward model at each case's
reference (observed orders, Richardson extrapolation, errors in sigma units, linearised parameter
bias, CPU time per mesh; see bench/studies/convergence.py)."""

from __future__ import annotations

NAME = "convergence"
HELP = (
    "mesh convergence study of FE cases at their reference: families of refined meshes per "
    "element (graded), observed order, Richardson-extrapolated force and front-face field, each "
    "mesh's error in sigma and linearised parameter bias, CPU time; resumable"
)


def _sizes(text: str) -> tuple[int, ...]:
    from bench.commands._args import ArgumentTypeError

    try:
        sizes = tuple(int(t) for t in text.split(","))
    except ValueError:
        sizes = ()
    if len(sizes) < 3 or any(n < 2 for n in sizes) or list(sizes) != sorted(set(sizes)):
        raise ArgumentTypeError(
            f"{text!r} is out of range: at least three increasing whole numbers >= 2, "
            "comma-separated (n gives the 8-node mesh n,n,2n)"
        )
    return sizes


def _grading(text: str) -> float:
    import math

    from bench.commands._args import ArgumentTypeError

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 1.0):
        raise ArgumentTypeError(f"{text!r} is out of range: a number >= 1 (1 = uniform)")
    return value


def _element(text: str) -> str:
    from bench.commands._args import ArgumentTypeError
    from problems.fe.mesh import ELEMENTS

    if text not in ELEMENTS:
        raise ArgumentTypeError(f"{text!r} is unknown; allowed: {', '.join(ELEMENTS)}")
    return text


def _margins(text: str) -> tuple[float, ...]:
    """Plate margins, mm: a comma-separated list of numbers in [0, 75) (half the cube's height;
    :class:`problems.inverse.build.Region`), returned sorted without repeats."""
    from bench.commands._args import comma_list, float_in
    from problems.fe.mesh import SIZE_MM

    margin = float_in(0.0, SIZE_MM[2] / 2, high_open=True, unit="mm")
    return tuple(sorted(set(comma_list(margin, what="margin")(text))))


def add_arguments(p) -> None:
    from bench.commands._args import add_quiet_argument, comma_list, mesh_spec, output_dir
    from bench.studies.convergence import (
        DEFAULT_COMPARE,
        DEFAULT_GRADING,
        DEFAULT_PLATE_MARGINS,
        DEFAULT_SIZES,
    )

    p.add_argument("cases", nargs="+", metavar="CASE", help="FE case name(s), or all")
    p.add_argument(
        "--sizes",
        type=_sizes,
        default=DEFAULT_SIZES,
        help="family sizes n, comma-separated, increasing, >= 3 of them: the 8-node meshes "
        "n,n,2n, the 27-node n/2,n/2,n (n even; same nodes) "
        f"(default {','.join(map(str, DEFAULT_SIZES))})",
    )
    p.add_argument(
        "--hex27-sizes",
        type=_sizes,
        help="sizes n of the hex27 family (even; default --sizes): its meshes n/2,n/2,n have "
        "the nodes of the 8-node n,n,2n",
    )
    p.add_argument(
        "--grading",
        type=_grading,
        default=DEFAULT_GRADING,
        help=f"grading ratio of the families, >= 1 (1 = uniform; default {DEFAULT_GRADING:g})",
    )
    p.add_argument(
        "--elements",
        type=comma_list(_element, what="element"),
        default=("hex8",),
        help="one family per element: hex8, hex27 (default hex8)",
    )
    p.add_argument(
        "--compare",
        type=mesh_spec,
        nargs="+",
        metavar="MESH",
        default=DEFAULT_COMPARE,
        help="mesh specs judged against the extrapolation, not part of it, space-separated "
        f"(default {' '.join(DEFAULT_COMPARE)})",
    )
    p.add_argument("--no-compare", action="store_true", help="no comparison meshes")
    p.add_argument(
        "--plain",
        type=mesh_spec,
        nargs="+",
        metavar="MESH",
        default=(),
        help="meshes of the study solved without the exact Jacobian, through the response cache "
        "shared with `femubench data` (~2/3 of the cost; their errors are measured, their own "
        "bias is not): for the finest meshes, space-separated",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/convergence/<case>; with several cases "
        "DIR/<case>)",
    )
    p.add_argument(
        "--plate-margins",
        type=_margins,
        metavar="MM,...",
        help="plate margins of the measurement-region analysis of a study with the model-error "
        "data mesh, mm, comma-separated, each in [0, 75) (default "
        f"{','.join(f'{x:g}' for x in DEFAULT_PLATE_MARGINS)}; with --render: redo the analysis "
        "from the mesh records, no FE solve)",
    )
    p.add_argument(
        "--render",
        action="store_true",
        help="solve nothing: re-draw from the output folder (and with --plate-margins redo the "
        "plate-margin analysis from its mesh records)",
    )
    add_quiet_argument(p)


def main(args) -> int:
    from pathlib import Path

    from bench.studies import case_names, default_output_dir, existing_dir, render_from
    from bench.studies.convergence import (
        DEFAULT_PLATE_MARGINS,
        STUDY,
        family_label,
        family_specs,
        render_convergence,
        render_overview,
        run_convergence,
        update_plate_margin,
    )
    from problems.fe.mesh import discretisation_key
    from problems.inverse.cases import get_case

    cases = case_names(args.cases)
    analytic = [c for c in cases if get_case(c).is_analytic]
    if analytic:
        raise ValueError(f"case {analytic[0]}: the convergence study needs an FE case")
    sizes = {"hex8": args.sizes, "hex27": args.hex27_sizes or args.sizes}
    if "hex27" in args.elements and any(n % 2 for n in sizes["hex27"]):
        option = "--hex27-sizes" if args.hex27_sizes else "--sizes"
        raise ValueError(
            f"{option} {','.join(map(str, sizes['hex27']))}: hex27 families need even sizes "
            "(n/2 elements per side)"
        )
    families = {
        family_label(e, args.grading): family_specs(sizes[e], args.grading, e)
        for e in args.elements
    }
    compare = () if args.no_compare else args.compare
    seen = {discretisation_key(m): m for specs in families.values() for m in specs}
    for spec in compare:  # one row per discretisation
        key = discretisation_key(spec)
        if key in seen:
            raise ValueError(
                f"--compare {spec}: the same discretisation as {seen[key]} ({key}); give each "
                "mesh once"
            )
        seen[key] = spec
    for spec in args.plain:
        if discretisation_key(spec) not in seen:
            raise ValueError(
                f"--plain {spec}: not a mesh of this study; allowed: one of "
                f"{', '.join(seen.values())}"
            )
    outs = {
        name: args.out if args.out is None or len(cases) == 1 else Path(args.out) / name
        for name in cases
    }

    def report(rec, reused):
        if not args.quiet:
            what = "reused" if reused else f"{rec['cpu_s']:.1f} CPU s, {rec['wall_s']:.1f} s wall"
            state = "" if rec["ok"] else f" FAILED: {rec['message']}"
            print(f"  {rec['case']} {rec['mesh']} ({rec['dofs']} dofs): {what}{state}", flush=True)

    for name in cases:
        if args.render:
            folder = existing_dir(STUDY, name, outs[name])
            if update_plate_margin(folder, args.plate_margins or ()):
                print(f"wrote {folder / 'convergence.json'} (rounding floor, plate margins)")
        else:
            margins = args.plate_margins or DEFAULT_PLATE_MARGINS
            folder = run_convergence(
                name, families, compare, outs[name], report, margins, args.plain
            )
        print(f"wrote {render_from(render_convergence, folder)}")
    default_root = default_output_dir(STUDY, cases[0]).parent
    roots = []
    if args.out is None or len(cases) > 1:
        roots.append(Path(args.out) if args.out else default_root)
    # a further study in a folder of the default root (e.g. results/studies/convergence/hex27-g8,
    # or one of its case folders) appears in the default root's overview too
    out = Path(args.out).resolve() if args.out else None
    if out is not None and default_root.resolve() in out.parents and default_root not in roots:
        roots.append(default_root)
    for root in roots:
        print(f"wrote {render_overview(root)}")
    return 0
