"""``femubench data``: make (or check) pseudo-experimental data sets."""
from __future__ import annotations

NAME = "data"
HELP = "Compute a pseudo-experimental data set of a case (reference response on a finer mesh, noised, rounded)."


def add_arguments(p) -> None:
    p.add_argument("case", help="case name, or 'all' for the nine cases")
    p.add_argument("--mesh", default="fine", help="data mesh (default fine; never the inverse model's mesh)")
    p.add_argument("--resolution-um", type=float, default=1.0, help="displacement rounding, um (default 1.0)")
    p.add_argument("--noise-um", type=float, default=0.0, help="Gaussian displacement noise std, um (default 0)")
    p.add_argument("--force-resolution-kN", type=float, default=0.1, help="force rounding, kN (default 0.1)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--route", choices=["fe", "dic"], default="fe",
                   help="fe: displacements from the FE field; dic: rendered speckle images correlated by DIC")
    p.add_argument("--out", metavar="FILE", help="write here (default: the shipped file or the cache)")
    p.add_argument("--check", action="store_true",
                   help="recompute and compare byte for byte with the existing file (exit 1 on a difference)")


def main(args) -> int:
    from dataclasses import replace
    from pathlib import Path

    from tqdm import tqdm

    from problems.inverse.cases import CASES, get_case
    from problems.inverse.data import DataSettings, cached_path, default_path, make_data, save

    names = list(CASES) if args.case == "all" else [get_case(args.case).name]
    settings = DataSettings(mesh=args.mesh, resolution_um=args.resolution_um, noise_um=args.noise_um,
                            force_resolution_kN=args.force_resolution_kN, seed=args.seed, route=args.route)
    status = 0
    for name in tqdm(names, desc="data sets", disable=len(names) == 1):
        path = Path(args.out) if args.out else (default_path(name) if settings == DataSettings() else cached_path(name, settings))
        ds = make_data(name, replace(settings), progress=True)
        text = ds.to_json()
        if args.check:
            same = path.exists() and path.read_text() == text
            print(f"{name}: {'identical' if same else 'DIFFERS from'} {path}")
            status |= 0 if same else 1
            continue
        save(ds, path)
        print(f"{name}: wrote {path} (hash {ds.hash[:12]}, {len(ds.values)} values)")
    return status
