"""Up-front resource checks: refuse a mesh, a sample or an ensemble whose arrays cannot fit in
memory before any work is done (one line naming the option, the value, the estimate and the limit).

Estimates are lower bounds, in bytes:

* :func:`mesh_operator_bytes` — the sparse operators of one Newton solve on a mesh: the tangent,
  its symmetric part and the permuted free-free block, each ~81 non-zeros per solved dof (a node
  of the structured hexahedral grid couples with 27 nodes x 3 dofs), 12 bytes per non-zero
  (float64 value + int32 index). The Cholesky factor comes on top (it fills in faster than the
  matrix grows), so a refused mesh could never run. ``fine`` (27 783 solved dofs): ~81 MB.
* :func:`sample_bytes` — a (rows x columns) float64 array, e.g. a Sobol sample N (d + 2) x d or
  an MCMC chain steps x walkers x n.

The limit is :data:`MEMORY_FRACTION` of the physical memory (:func:`physical_memory_bytes`;
``FEMUBENCH_MEMORY_BYTES`` overrides it, e.g. for tests or a cgroup-limited machine).
"""

from __future__ import annotations

import os

MEMORY_FRACTION = 0.5  #: refuse estimates above this fraction of the physical memory
NNZ_PER_DOF = 81  #: non-zeros per row of the hexahedral stiffness (27 nodes x 3 dofs)
BYTES_PER_NNZ = 12  #: float64 value + int32 column index
OPERATOR_COPIES = 3  #: tangent, its symmetric part, the permuted free-free block


def physical_memory_bytes() -> int:
    """Physical memory of the machine, bytes (``FEMUBENCH_MEMORY_BYTES`` if set)."""
    env = os.environ.get("FEMUBENCH_MEMORY_BYTES")
    if env:
        return int(float(env))
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not POSIX: no check
        return 1 << 62


def format_bytes(n: float) -> str:
    """``"81 MB"``, ``"71 GB"``, ``"3.2 TB"`` (decimal units)."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.2g} {unit}" if n / size < 10 else f"{n / size:.0f} {unit}"
    return f"{n:.0f} B"


def mesh_operator_bytes(spec) -> float:
    """Lower bound of the memory of the sparse operators of one solve on mesh ``spec``, bytes."""
    from bench.progress import solved_dofs

    return float(solved_dofs(spec)) * NNZ_PER_DOF * BYTES_PER_NNZ * OPERATOR_COPIES


def sample_bytes(*shape: float) -> float:
    """Memory of a float64 array of ``shape``, bytes."""
    n = 8.0
    for s in shape:
        n *= float(s)
    return n


def check_memory(estimate: float, what: str) -> None:
    """ValueError (one line: ``what``, the estimate, the limit) when ``estimate`` bytes exceed
    :data:`MEMORY_FRACTION` of the physical memory."""
    total = physical_memory_bytes()
    limit = MEMORY_FRACTION * total
    if estimate > limit:
        raise ValueError(
            f"{what} needs at least {format_bytes(estimate)} of memory, more than half the "
            f"{format_bytes(total)} of this machine (allowed: <= {format_bytes(limit)})"
        )


def check_mesh_memory(spec, what: str | None = None) -> None:
    """:func:`check_memory` of the operators of mesh ``spec``; ``what`` names it (default
    ``mesh SPEC``)."""
    from bench.progress import solved_dofs

    check_memory(
        mesh_operator_bytes(spec),
        f"{what or f'mesh {spec!r}'} ({solved_dofs(spec):,} solved dofs)",
    )
