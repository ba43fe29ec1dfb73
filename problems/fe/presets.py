"""Named meshes: what a preset name in a mesh spec stands for
(:func:`problems.fe.mesh.parse_mesh_spec`).

A preset only names a discretisation: every run is keyed by the spelled-out discretisation
(:func:`problems.fe.mesh.discretisation_key`, e.g. ``converged`` -> ``15,15,30:g16:hex27``), so
this file is not part of the code that computes a response and is left out of the response
cache's code hash (:data:`problems.inverse.response_cache.NOT_RESPONSE_CODE`): renaming or
re-pointing a preset keeps every cached run valid.
"""

from __future__ import annotations

#: named presets: ``coarse`` ~ 400-600, ``paper`` ~ 5 000 (paper: 4 960), ``fine`` 15 000-20 000
#: elements
MESH_PRESETS: dict[str, tuple[int, int, int]] = {
    "coarse": (6, 6, 12),  # 432 elements, 12.5 mm cubes
    # 5 096 elements (was 14 x 14 x 25: nz even gives the exact eighth model)
    "paper": (14, 14, 26),
    "fine": (20, 20, 40),  # 16 000 elements, 3.75 mm cubes
    # 27 648 elements, 3.125 mm cubes: the former model-error data mesh (not converged: 5.3 sigma,
    # +0.35 % in force on linear-compression; docs/fe_model.md)
    "xfine": (24, 24, 48),
}
#: named full specs (size and tokens): ``converged`` is the model-error tier's data mesh, the
#: 27-node 15 x 15 x 30 quarter graded with ratio 16 (89 373 dofs; against the five-mesh
#: extrapolation of the convergence study 0.11-0.15 sigma RMS and +0.016 to +0.044 % in force on
#: the nine cases: docs/fe_model.md, "The converged reference"). Until stop 38 it was
#: ``12,12,24:g8:hex27`` (0.25-0.42 sigma, +0.042 to +0.095 %: short of the criterion).
SPEC_PRESETS: dict[str, str] = {"converged": "15,15,30:g16:hex27"}


def spell_out(spec: str) -> str:
    """``spec`` with a :data:`SPEC_PRESETS` name as its size replaced by the spec it names today
    (``converged:quarter`` -> ``15,15,30:g16:hex27:quarter``); any other spec unchanged (a
    :data:`MESH_PRESETS` name, ``NX,NY,NZ[:TOKEN...]``, ``auto``, ``""``). For keys and stored
    settings, whose meaning must not change when a preset is re-pointed."""
    base, sep, rest = spec.partition(":")
    return SPEC_PRESETS[base.strip()] + sep + rest if base.strip() in SPEC_PRESETS else spec
