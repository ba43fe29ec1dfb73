"""The cross-check run: for each dilatancy angle, the mapping, the single element, the tangent audit
(first angle only) and the quarter cube; writes ``opensees_dp.json`` into the output folder.
Figures: :func:`bench.crosscheck.figures.render_crosscheck` (from that file alone).
"""

from __future__ import annotations

import json
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from bench.crosscheck.loader import load_opensees, openseespy_version
from bench.crosscheck.mapping import REFERENCE, opensees_parameters, tension_cutoff_I1
from bench.crosscheck.report import REPORT_FILE, jsonable, slim


@dataclass
class CrosscheckRun:
    """What :func:`run_crosscheck` computed and wrote."""

    # everything, including the per-point grids (for the printed tables)
    report: dict
    dir: Path
    paths: list[Path] = field(default_factory=list)


def run_crosscheck(
    out,
    *,
    mesh: str = "coarse",
    psis=(35.0, 15.0),
    steps: int = 10,
    element_steps: int = 60,
    skip_cube: bool = False,
    all_strategies: bool = False,
) -> CrosscheckRun:
    """Run the comparisons (needs openseespy: :class:`~bench.crosscheck.loader.OpenSeesUnavailable`
    otherwise) and write ``out/opensees_dp.json``. ``psis`` in degrees (<= beta = 35), ``steps``
    cube snapshots, ``element_steps`` single-element steps."""
    from bench.crosscheck.cube import cube
    from bench.crosscheck.single_element import single_element
    from bench.crosscheck.tangent import tangent_audit

    load_opensees()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    report = {
        "openseespy": openseespy_version(),
        "reference": REFERENCE,
        "mappings": [],
        "single_element": [],
        "cube": [],
        "tangent_audit": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        for psi in psis:
            p = {**REFERENCE, "psi": float(psi)}
            osp = opensees_parameters(**p)
            report["mappings"].append(
                {"psi": p["psi"], "opensees": osp, "tension_cutoff_I1": tension_cutoff_I1(osp)}
            )
            report["single_element"].append(single_element(p, element_steps, Path(tmp)))
            if psi == psis[0]:
                report["tangent_audit"] = tangent_audit(osp, Path(tmp))
            if not skip_cube:
                report["cube"].append(cube(p, mesh, steps, all_strategies, Path(tmp)))
    report["wall_s"] = time.perf_counter() - t0
    path = out / REPORT_FILE
    path.write_text(json.dumps(jsonable(slim(report)), indent=1))
    return CrosscheckRun(report, out, [path])
