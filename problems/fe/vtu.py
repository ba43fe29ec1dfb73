"""Export of a forward run to VTU files (one per snapshot) and a ParaView ``.pvd`` collection."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from problems.fe.newton import Response

#: meshio cell type of the 8- and 27-node hexahedra (their node orders are VTK's)
_CELL_TYPES = {8: "hexahedron", 27: "hexahedron27"}


def write_vtu(response: Response, directory: str | Path, stem: str = "cube") -> list[Path]:
    """Write ``stem_NNNN.vtu`` for every snapshot and ``stem.pvd``; returns the VTU paths.

    Cells are VTK hexahedra (type 12) or, for 27-node meshes, triquadratic hexahedra (type 29,
    meshio ``hexahedron27``). Point data: ``displacement`` (mm). Cell data: ``stress`` (6 Voigt
    components, MPa, in the order xx, yy, zz, yz, xz, xy), ``von_mises`` (MPa), and every
    material history variable (e.g. ``eqps``); all element means.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    mesh = response.mesh
    paths = []
    for k, _top in enumerate(response.snapshots_mm):
        s = response.stress[k]
        dev = s[:, :3] - s[:, :3].mean(axis=1, keepdims=True)
        vm = np.sqrt(1.5 * (dev**2).sum(axis=1) + 3.0 * (s[:, 3:] ** 2).sum(axis=1))
        cell_data = {"stress": [s], "von_mises": [vm]}
        for j, name in enumerate(response.state_names):
            cell_data[name] = [response.state[k, :, j]]
        path = out / f"{stem}_{k:04d}.vtu"
        meshio.write(
            path,
            meshio.Mesh(
                mesh.nodes,
                [(_CELL_TYPES[mesh.elements.shape[1]], mesh.elements)],
                point_data={"displacement": response.displacements[k]},
                cell_data=cell_data,
            ),
        )
        paths.append(path)
    entries = "\n".join(
        f'    <DataSet timestep="{t:.6g}" file="{p.name}"/>'
        for t, p in zip(response.snapshots_mm, paths)
    )
    (out / f"{stem}.pvd").write_text(
        '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
        f"  <Collection>\n{entries}\n"
        "  </Collection>\n</VTKFile>\n"
    )
    return paths
