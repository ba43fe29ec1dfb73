"""The DIC route of the pseudo-experimental data: FE response -> speckle images -> IC-GN DIC.

The FE front-face field of each snapshot is handed to :func:`problems.dic.measure_front_face`
as the elements' own interpolant of the front-face nodal displacements (bilinear on 8-node,
biquadratic on 27-node meshes); the measured displacements and
their DIC standard deviations replace the FE values. Points whose correlation failed get zero
value and infinite standard deviation: they carry no weight in the objective. The covariance is
taken diagonal: on the 5 mm grid the 21 px subsets do not overlap, so points are independent, and
the u_h-u_v covariance of one point is small for an isotropic speckle (it is kept in ``meta``).
The images (PackBits TIFF) and a Fig.-2-like figure of a few subsets (reference, warped,
deformed) are written to the ``image_dir`` the caller gives (``femubench data`` and the data
cache use ``<data file stem>__dic_images/`` next to the data file); they are not part of the
data file: camera, speckle and DIC settings and the seed regenerate them.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from problems.fe.front_face import front_face_stencil


def front_face_fields(response) -> list:
    """One callable ``field(y_mm, z_mm) -> (u_y, u_z)`` per snapshot (quarter coordinates, mm): the
    elements' own interpolation of the front-face nodal displacements, bilinear on 8-node and
    biquadratic on 27-node meshes (:func:`problems.fe.front_face.front_face_stencil`, the same
    field the FE route samples at the grid points). Points must lie on the face (the image
    renderer clamps them onto it)."""
    mesh = response.mesh
    fields = []
    for u in response.displacements:

        def field(y, z, u=u):
            shape = np.shape(y)
            cols, w = front_face_stencil(mesh, np.column_stack([np.ravel(y), np.ravel(z)]))
            return (
                np.einsum("ij,ij->i", w, u[cols, 1]).reshape(shape),
                np.einsum("ij,ij->i", w, u[cols, 2]).reshape(shape),
            )

        fields.append(field)
    return fields


def measure_by_dic(response, points, *, seed: int = 0, progress: bool = True, image_dir=None):
    """Front-face displacements of ``response`` at ``points`` (m, 2) mm measured by DIC on rendered
    images.

    Returns ``(u_h (N, m), u_v (N, m), std (2, N, m), meta)`` in mm; points whose correlation failed
    get zero value and infinite standard deviation. ``image_dir``: where the images and the
    subset panels go (None: not written).
    """
    from problems.dic import measure_front_face

    m = measure_front_face(
        front_face_fields(response),
        points,
        seed=seed,
        progress=progress,
        image_dir=image_dir,
        figure=True,
    )
    ok = m.converged
    u_h = np.where(ok, m.u_h, 0.0)
    u_v = np.where(ok, m.u_v, 0.0)
    std = np.stack([np.where(ok, m.std_h, np.inf), np.where(ok, m.std_v, np.inf)])
    meta = {
        "dic": {
            "camera": asdict(m.camera),
            "speckle": asdict(m.speckle),
            "dic": asdict(m.dic),
            "seed": m.seed,
            "converged_fraction": float(ok.mean()),
            "median_std_mm": float(np.nanmedian(m.std_h)),
            "max_abs_cov_hv_mm2": float(np.nanmax(np.abs(m.cov_hv))) if ok.any() else None,
        }
    }
    return u_h, u_v, std, meta
