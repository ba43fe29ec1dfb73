"""Digital image correlation: speckle images rendered from a displacement field, IC-GN subset
correlation, and the DIC measurement route of the inverse problem. See ``docs/dic.md``.

Modules: ``speckle`` (pattern, analytic rendering, camera, noise), ``warp`` (inverse mapping,
symmetry), ``imageio`` (TIFF/PNG/BMP), ``interpolate`` (B-splines), ``correlate`` (IC-GN),
``seed`` (FFT guess, neighbour graph), ``pipeline`` (``measure_front_face``), ``subsets`` (the
data of the Fig.-2-like subset figure, drawn by ``bench.dic_figures``).
"""

from problems.dic.correlate import Correlator, DICConfig, DICResult, grid_points
from problems.dic.imageio import read_image, write_image
from problems.dic.pipeline import DICMeasurement, measure_front_face, render_images
from problems.dic.speckle import CameraConfig, SpeckleConfig, SpecklePattern

__all__ = [
    "CameraConfig",
    "Correlator",
    "DICConfig",
    "DICMeasurement",
    "DICResult",
    "SpeckleConfig",
    "SpecklePattern",
    "grid_points",
    "measure_front_face",
    "read_image",
    "render_images",
    "write_image",
]
