"""``femubench data``: make (or check) pseudo-experimental data sets.

Where a data set is written: ``--out FILE`` for one case, ``--out DIR`` (``DIR/<case>.json``) for
``all``; without ``--out``, default settings go to the default data set (shipped, or in
``$FEMUBENCH_DATA_DIR``) — only with ``--force`` when that file exists — and other settings to the
cache (``$FEMUBENCH_CACHE_DIR``). DIC-route images go next to the data file, in
``<stem>__dic_images/``.
"""

from __future__ import annotations

from problems.fe.presets import SPEC_PRESETS

NAME = "data"
HELP = (
    "Compute a pseudo-experimental data set of a case: the reference response, rounded (and "
    "noised), in the model-error tier (the converged mesh "
    f"{SPEC_PRESETS['converged']}) or the consistent tier (the inverse model's mesh)."
)


def add_arguments(p) -> None:
    from bench.commands._args import add_quiet_argument, mesh_spec, nonneg_float, nonneg_int

    p.add_argument("case", help="case name, or 'all' for the nine cases")
    p.add_argument(
        "--tier",
        choices=["model-error", "consistent"],
        default="model-error",
        help="model-error: made on a discretisation finer than any model of the inverse loop; "
        "consistent: made with the inverse model's own mesh (default model-error)",
    )
    p.add_argument(
        "--mesh",
        default=None,
        type=mesh_spec,
        help=f"data mesh (default: {SPEC_PRESETS['converged']}, the preset converged, for the "
        "model-error tier; for the consistent tier the inverse model's mesh, default coarse)",
    )
    p.add_argument(
        "--resolution-um",
        type=nonneg_float,
        default=1.0,
        help="displacement rounding, um, >= 0 (default 1.0; 0: no rounding)",
    )
    p.add_argument(
        "--noise-um",
        type=nonneg_float,
        default=0.0,
        help="Gaussian displacement noise std, um, >= 0 (default 0)",
    )
    p.add_argument(
        "--force-resolution-kN",
        type=nonneg_float,
        default=0.1,
        help="force rounding, kN, >= 0 (default 0.1; 0: no rounding)",
    )
    p.add_argument("--seed", type=nonneg_int, default=0, help="noise seed, >= 0 (default 0)")
    p.add_argument(
        "--route",
        choices=["fe", "dic"],
        default="fe",
        help="fe: displacements from the FE field; dic: rendered speckle images correlated by DIC "
        "(images in <data file stem>__dic_images/ next to the data file)",
    )
    p.add_argument(
        "--out",
        metavar="FILE|DIR",
        help="write here: a file for one case, a directory (DIR/<case>.json) for 'all' "
        "(default: the shipped file for default settings, else the cache)",
    )
    p.add_argument(
        "--force", action="store_true", help="allow overwriting a shipped (default) data set"
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="recompute and compare byte for byte with the existing file (exit 1 on a "
        "difference); solves afresh, not from the response cache",
    )
    add_quiet_argument(p)


def target_paths(names: list[str], settings, out: str | None, *, every: bool) -> dict:
    """``{case: path}`` each data set is written to (or checked against); ValueError for an
    ``--out`` that does not fit: a file name for ``all``."""
    from pathlib import Path

    from problems.inverse.data import cached_path, default_path, is_default

    if out is None:
        default = is_default(settings)
        return {
            n: default_path(n, settings.tier) if default else cached_path(n, settings)
            for n in names
        }
    out = Path(out)
    if every:
        if (out.exists() and not out.is_dir()) or out.suffix == ".json":
            raise ValueError(
                f"--out {out}: 'all' writes one file per case, so --out must be a directory"
            )
        return {n: out / f"{n}.json" for n in names}
    if out.exists() and not out.is_dir() and out.suffix != ".json":
        raise ValueError(f"--out {out}: a data set is a .json file (or give a directory)")
    parent = next((q for q in out.parents if q.exists()), None)
    if parent is not None and not parent.is_dir():
        raise ValueError(f"--out {out}: {parent} is a file, not a folder")
    return {n: out / f"{n}.json" if out.is_dir() else out for n in names}


def refuse_shipped(paths, force: bool) -> None:
    """ValueError if a path is an existing default data set (shipped, or in ``$FEMUBENCH_DATA_DIR``)
    and ``force`` is not given."""
    from problems.inverse.data import SHIPPED_DIR, data_dir

    protected = {SHIPPED_DIR.resolve(), data_dir().resolve()}
    for path in paths:
        if not force and path.exists() and path.resolve().parent.parent in protected:
            raise ValueError(f"{path} is a shipped data set; add --force to overwrite it")


def main(args) -> int:
    from dataclasses import replace

    from tqdm import tqdm

    from bench.dic_figures import PANELS_FILE, render_subsets
    from bench.progress import enabled, warn_if_long
    from problems.inverse.cases import CASES, get_case
    from problems.inverse.data import dic_image_dir, make_data, save, tier_settings

    every = args.case == "all"
    names = list(CASES) if every else [get_case(args.case).name]
    mesh = {"mesh": args.mesh} if args.mesh else {}
    settings = tier_settings(
        args.tier,
        **mesh,
        resolution_um=args.resolution_um,
        noise_um=args.noise_um,
        force_resolution_kN=args.force_resolution_kN,
        seed=args.seed,
        route=args.route,
    )
    paths = target_paths(names, settings, args.out, every=every)
    if not args.check:
        from bench.commands._args import not_writable

        for path in paths.values():
            if not_writable(path):
                raise ValueError(f"--out {path} is not writable (permission denied)")
    if not args.check:
        refuse_shipped(paths.values(), args.force)
    warn_if_long(NAME, len(names), settings.mesh, what=f"{len(names)} data set(s)")
    status = 0
    show = enabled(args.quiet)
    for name in tqdm(names, desc="data sets", disable=len(names) == 1 or not show):
        path = paths[name]
        images = None if args.check else dic_image_dir(path)
        ds = make_data(
            name, replace(settings), progress=show, image_dir=images, reuse=not args.check
        )
        text = ds.to_json()
        if args.check:
            same = path.exists() and path.read_text() == text
            print(f"{name}: {'identical' if same else 'DIFFERS from'} {path}")
            status |= 0 if same else 1
            continue
        save(ds, path)
        if settings.route == "dic" and (images / PANELS_FILE).is_file():
            render_subsets(images)
        print(f"{name}: wrote {path} (hash {ds.hash[:12]}, {len(ds.values)} values)")
    return status
