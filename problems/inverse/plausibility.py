"""Plausibility checks where a number cannot be right: data in the wrong units, a final cost far
above the data's size, parameters on their bounds, a displacement beyond the specimen, points off
the face.

Refused (ValueError, one line naming the field, the value and what is allowed):

* :func:`check_displacement` — a top-plate displacement above :data:`MAX_NOMINAL_STRAIN` of the
  specimen's height (the FE model is small-strain; concrete fails below 1 % strain; 1.5 mm on the
  150 mm cube is the default): ``--displacement 1000`` on the cube;
* :func:`check_points` — front-face points off the quarter's face (they used to fail every
  evaluation, or be dropped silently by a plate margin).

Warned (:class:`PlausibilityWarning`, with the numbers; ``identify`` prints them, a suite run keeps
them in its record's ``warnings``): :func:`data_warnings` (all zero, displacements larger than
the plate's, a force no concrete can carry, points on a sliver of the face) and
:func:`result_warnings` (a final cost >= :data:`COST_FACTOR` x the number of data, which it
should be close to when model and data agree to the data's noise; parameters on a bound).
An FE identification issues the first with :func:`warn_data` before it runs and the second with
:func:`warn_result` when it has finished.

Units: mm, kN, MPa (= N/mm^2).
"""

from __future__ import annotations

import warnings

import numpy as np

#: a final cost this many times the number of data is implausible (its expected value ~ 1 x)
COST_FACTOR = 100.0
#: the largest top-plate displacement accepted, as a fraction of the specimen's height
MAX_NOMINAL_STRAIN = 0.1
#: a nominal stress (force over the whole section) above this is no concrete, MPa
MAX_STRESS_MPA = 1000.0
#: displacements larger than this multiple of the plate's are not of a point of the specimen
MAX_DISPLACEMENT_RATIO = 1.5
#: points spanning less than this fraction of the face along y and z suggest cm for mm
MIN_SPAN_FRACTION = 0.25
#: a parameter closer to a bound than this fraction of its range is "on the bound"
BOUND_FRACTION = 1e-6


class PlausibilityWarning(UserWarning):
    """A result or a data set whose numbers cannot be right (wrong units, wrong model, a box
    that excludes the answer)."""


def check_displacement(displacement_mm: float, height_mm: float, what: str = "displacement_mm"):
    """ValueError unless 0 < ``displacement_mm`` <= :data:`MAX_NOMINAL_STRAIN` x ``height_mm``."""
    limit = MAX_NOMINAL_STRAIN * height_mm
    if not displacement_mm <= limit:
        raise ValueError(
            f"{what} = {displacement_mm:g} mm is beyond the specimen (the FE model is "
            f"small-strain); allowed: <= {MAX_NOMINAL_STRAIN:.0%} of the {height_mm:g} mm "
            f"height = {limit:g} mm"
        )


def check_points(points, specimen_mm, what: str = "points") -> None:
    """ValueError naming how many of the (y, z) mm ``points`` lie off the quarter's front face
    y in [0, ly/2], z in [0, lz] of a specimen of extents ``specimen_mm``."""
    pts = np.asarray(points, float).reshape(-1, 2)
    half_y, height = specimen_mm[1] / 2.0, specimen_mm[2]
    tol = 1e-9 * height
    off = (
        (pts[:, 0] < -tol)
        | (pts[:, 0] > half_y + tol)
        | (pts[:, 1] < -tol)
        | (pts[:, 1] > height + tol)
    )
    if off.any():
        y, z = pts[np.argmax(off)]
        raise ValueError(
            f"{what}: {int(off.sum())} of {len(pts)} points lie off the front face (first: y = "
            f"{y:g}, z = {z:g} mm); allowed: y in [0, {half_y:g}] mm, z in [0, {height:g}] mm"
        )


def data_warnings(data) -> list[str]:
    """What is implausible about a :class:`~problems.inverse.data.Dataset` (messages, [] if
    nothing)."""
    out = []
    lx, ly, lz = data.settings.specimen_mm
    u = np.abs(np.concatenate([np.ravel(data.u_h), np.ravel(data.u_v)]))
    force = np.abs(np.asarray(data.reaction_kN, float))
    if not u.any() and not force.any():
        return [f"data of {data.case} are all zero (u_h, u_v and reaction_kN): nothing measured"]
    plate = float(np.max(np.abs(data.snapshots_mm))) if len(data.snapshots_mm) else 0.0
    if plate > 0 and u.max() > MAX_DISPLACEMENT_RATIO * plate:
        out.append(
            f"data of {data.case}: front-face displacements up to {u.max():.4g} mm exceed the "
            f"plate's {plate:g} mm (micrometres instead of mm?)"
        )
    stress = force.max() * 1e3 / (lx * ly)
    if stress > MAX_STRESS_MPA:
        out.append(
            f"data of {data.case}: a force of {force.max():.4g} kN is {stress:.3g} MPa on the "
            f"{lx:g} x {ly:g} mm section, beyond any concrete (> {MAX_STRESS_MPA:g} MPa; N "
            "instead of kN?)"
        )
    pts = np.asarray(data.points, float)
    if len(pts) and (
        pts[:, 0].max() < MIN_SPAN_FRACTION * ly / 2 and pts[:, 1].max() < MIN_SPAN_FRACTION * lz
    ):
        out.append(
            f"data of {data.case}: the points reach only y = {pts[:, 0].max():g} mm, z = "
            f"{pts[:, 1].max():g} mm of the {ly / 2:g} x {lz:g} mm face (cm instead of mm?)"
        )
    return out


def result_warnings(result, n_data: int | None, lower, upper) -> list[str]:
    """What is implausible about a finished RunResult: a cost >= :data:`COST_FACTOR` x ``n_data``
    (skipped when ``n_data`` is None) and parameters on a bound of ``[lower, upper]``."""
    out = []
    cost = float(result.cost)
    if n_data and np.isfinite(cost) and cost >= COST_FACTOR * n_data:
        out.append(
            f"final cost {cost:.4g} is {cost / n_data:.3g} x the {n_data} data (expected about "
            f"1 x when model and data agree to the data's noise): data in the wrong units (N for "
            f"kN, um or cm for mm), or a model error the treatment does not remove"
        )
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    x = np.asarray(result.x, float)
    if len(x) == len(lo):
        tol = BOUND_FRACTION * (hi - lo)
        on = [
            f"{n} = {v:.6g} ({'lower' if v - a <= t else 'upper'} bound)"
            for n, v, a, b, t in zip(result.parameter_names, x, lo, hi, tol)
            if v - a <= t or b - v <= t
        ]
        if on:
            out.append(
                f"{len(on)} of {len(x)} parameters on a bound: {', '.join(on)} (the answer may "
                "lie outside the box, or the data cannot be fitted)"
            )
    return out


def n_data(data, region) -> int:
    """Number of data the objective fits in ``region``: the measured (finite standard deviation)
    displacements plus the forces."""
    keep = region.mask(data.points, data.settings.specimen_mm[2])
    return int(np.isfinite(data.std_u_mm[:, :, keep]).sum()) + len(data.reaction_kN)


def warn_data(data) -> list[str]:
    """Issue a :class:`PlausibilityWarning` for each of :func:`data_warnings` (before any run);
    returns the messages."""
    return _warn(data_warnings(data))


def warn_result(case, data, region, result) -> list[str]:
    """Issue a :class:`PlausibilityWarning` for each of :func:`result_warnings` of a finished FE
    identification of ``case`` on ``data`` in ``region``; returns the messages."""
    return _warn(result_warnings(result, n_data(data, region), case.lower, case.upper))


def _warn(messages: list[str]) -> list[str]:
    for message in messages:
        warnings.warn(PlausibilityWarning(message), stacklevel=3)
    return messages
