"""Subset DIC: ZNSSD criterion, inverse-compositional Gauss-Newton (IC-GN), first-order shapes.

Notation (one subset, ``P = (2h + 1)^2`` pixels at offsets ``xi = (dx, dy)`` from its integer
centre ``x0``):

* shape parameters ``p = (u, u_x, u_y, v, v_x, v_y)``, warp
  ``W(xi; p) = [(1 + u_x) dx + u_y dy + u, v_x dx + (1 + v_y) dy + v]``, i.e. the 3 x 3 matrix
  ``[[1 + u_x, u_y, u], [v_x, 1 + v_y, v], [0, 0, 1]]``;
* reference ``f_i = f(x0 + xi_i)``, deformed ``g_i = g(x0 + W(xi_i; p))`` (B-spline interpolated);
* ZNSSD ``C = sum_i (f~_i / Df - g~_i / Dg)^2`` with ``f~ = f - mean f``, ``Df = ||f~||`` (same
  for g); ``C = 2 (1 - ZNCC)``, so minimising ZNSSD maximises ZNCC.

IC-GN (Baker & Matthews; Pan et al. 2013): with the steepest-descent images
``S_i = grad f(x0 + xi_i) dW/dp = [f_x, f_x dx, f_x dy, f_y, f_y dx, f_y dy]`` and the constant
Hessian ``H = sum_i S_i^T S_i`` (both from the reference only, computed once per subset), each
iteration evaluates

    r_i = f~_i - (Df / Dg) g~_i,      dp = -H^{-1} sum_i S_i^T r_i,
    W(p) <- W(p) o W(dp)^{-1},

until ``|dp| = sqrt(du^2 + dv^2 + h^2 (du_x^2 + du_y^2 + dv_x^2 + dv_y^2)) < tol``.

Everything is vectorised over subsets: per iteration one ``map_coordinates`` call over all
active subsets' ``P`` points, two GEMMs for ``S^T r``, batched 6 x 6 products; converged or
failed subsets leave the active set.

Uncertainty: near the solution ``dp = H^{-1} sum S_i^T e_i`` with ``e_i`` the grey-level noise of
the residual (noise of ``f`` minus noise of ``g``), so ``Cov(p) = 2 sigma^2 H^{-1}`` with ``sigma``
the grey-level noise of one image. ``sigma`` is given (``DICConfig.noise_sigma``) or estimated per
subset from the converged residual: ``s^2 = sum r_i^2 / (P - 8)`` (6 shape parameters, mean and
scale) estimates ``sigma^2 (1 + gamma)``, where ``gamma(t_x, t_y) <= 1`` is the variance gain of
interpolating white noise at the sub-pixel fraction of ``(u, v)``; hence
``sigma^2 = s^2 / (1 + gamma)``.

Initial guesses: integer FFT cross-correlation at a few seed points, then reliability-guided
propagation: in rounds, every unsolved point next to solved ones starts from its most
reliable (highest-ZNCC) solved neighbour's warp, carried over the offset by the first-order
shape; with a previous snapshot's solution, that is the start and propagation only fills in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from problems.dic._kernels import get_step
from problems.dic.interpolate import SUPPORTED_ORDERS, BSplineImage, noise_gain
from problems.dic.seed import integer_guess, neighbour_graph, seed_candidates

PARAM_NAMES = ("u", "u_x", "u_y", "v", "v_x", "v_y")


@dataclass(frozen=True)
class DICConfig:
    """Correlation settings (pixels unless stated).

    subset        : subset side (odd), e.g. 21 for 21 x 21 px
    step          : grid spacing of subset centres (for grids built from a ROI)
    order         : B-spline interpolation of the deformed image, 3 (bicubic) or 5 (biquintic)
    max_iter      : IC-GN iteration limit (reaching it = not converged)
    tol           : IC-GN stop criterion on |dp| (px at the subset edge)
    zncc_min      : a converged point with a lower final ZNCC is flagged as not converged
    search_radius : integer search range of the FFT seed guess
    seed_subset   : side of the (larger) subset used for the FFT seed guess; 0: 2 subset + 1
    n_seeds       : seed points tried first (centre and quadrant centres of the points)
    min_texture   : reference subsets whose grey-level std is below this are rejected
    noise_sigma   : grey-level noise of the images if known; None: estimated from residuals
    max_tries     : propagation attempts per point (each from a different neighbour)
    chunk         : subsets per vectorised batch (memory ~ chunk * subset^2 * 100 bytes)
    backend       : inner-loop back-end, 'scipy' or 'numba' (None: numba when installed)
    """

    subset: int = 21
    step: int = 10
    order: int = 3
    max_iter: int = 30
    tol: float = 1e-3
    zncc_min: float = 0.9
    search_radius: int = 32
    seed_subset: int = 0
    n_seeds: int = 5
    min_texture: float = 1.0
    noise_sigma: float | None = None
    max_tries: int = 3
    chunk: int = 2048
    backend: str | None = None

    def __post_init__(self):
        if not (
            isinstance(self.subset, (int, np.integer)) and self.subset >= 5 and self.subset % 2 == 1
        ):
            raise ValueError(
                f"subset = {self.subset!r}: the subset side must be an odd integer >= 5"
            )
        if not self.step >= 1:
            raise ValueError(f"step = {self.step!r}: the grid step must be >= 1 px")
        if self.order not in SUPPORTED_ORDERS:
            raise ValueError(f"order = {self.order!r}: use 3 (bicubic) or 5 (biquintic)")
        if not (self.max_iter >= 1 and self.tol > 0 and -1 <= self.zncc_min <= 1):
            raise ValueError("max_iter must be >= 1, tol > 0 and -1 <= zncc_min <= 1")
        if self.search_radius < 0 or self.n_seeds < 1 or self.max_tries < 1 or self.chunk < 1:
            raise ValueError("search_radius must be >= 0; n_seeds, max_tries and chunk >= 1")
        if self.backend not in (None, "scipy", "numba"):
            raise ValueError(f"backend = {self.backend!r}: use 'scipy', 'numba' or None")
        if self.noise_sigma is not None and not self.noise_sigma >= 0:
            raise ValueError(f"noise_sigma = {self.noise_sigma!r} must be >= 0 or None")

    @property
    def half(self) -> int:
        return self.subset // 2


@dataclass
class DICResult:
    """Correlation of one deformed image at ``n`` subset centres (pixels, x right, y down).

    Points that did not converge (or whose final ZNCC is below ``zncc_min``) have
    ``converged = False`` and NaN displacements, gradients and standard deviations.
    """

    x: np.ndarray  # (n,) subset centres, px (integers)
    y: np.ndarray
    params: np.ndarray  # (n, 6) p = (u, u_x, u_y, v, v_x, v_y)
    zncc: np.ndarray  # (n,) final ZNCC (NaN if never evaluated)
    iterations: np.ndarray  # (n,) IC-GN iterations of the final attempt
    converged: np.ndarray  # (n,) bool
    cov: np.ndarray  # (n, 6, 6) covariance of p, px^2
    noise_sigma: float = float("nan")  # grey-level noise per image estimated from residuals
    meta: dict = field(default_factory=dict)

    @property
    def u(self) -> np.ndarray:
        return self.params[:, 0]

    @property
    def v(self) -> np.ndarray:
        return self.params[:, 3]

    @property
    def dudx(self) -> np.ndarray:
        return self.params[:, 1]

    @property
    def dudy(self) -> np.ndarray:
        return self.params[:, 2]

    @property
    def dvdx(self) -> np.ndarray:
        return self.params[:, 4]

    @property
    def dvdy(self) -> np.ndarray:
        return self.params[:, 5]

    @property
    def std_u(self) -> np.ndarray:
        return np.sqrt(self.cov[:, 0, 0])

    @property
    def std_v(self) -> np.ndarray:
        return np.sqrt(self.cov[:, 3, 3])

    def at(self, xq: np.ndarray, yq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Displacements and their covariance at points ``(xq, yq)`` near the subset centres.

        Uses each subset's first-order shape: ``u(x0 + d) = u + u_x d_x + u_y d_y`` (same for v);
        ``xq, yq`` must be given per subset (shape ``(n,)``). Returns ``(u, v, cov)`` with
        ``cov`` of shape (n, 2, 2).
        """
        dx = np.asarray(xq, float) - self.x
        dy = np.asarray(yq, float) - self.y
        p = self.params
        u = p[:, 0] + p[:, 1] * dx + p[:, 2] * dy
        v = p[:, 3] + p[:, 4] * dx + p[:, 5] * dy
        J = np.zeros((len(dx), 2, 6))
        J[:, 0, 0], J[:, 0, 1], J[:, 0, 2] = 1.0, dx, dy
        J[:, 1, 3], J[:, 1, 4], J[:, 1, 5] = 1.0, dx, dy
        cov = J @ self.cov @ J.transpose(0, 2, 1)
        return u, v, cov


# --------------------------------------------------------------------------- input checks


def as_grey(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Validate a 2-D grey-level image and return it as float64."""
    a = np.asarray(image)
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D grey-level image, got an array of shape {a.shape}")
    if a.shape[0] < 5 or a.shape[1] < 5:
        raise ValueError(f"{name} is too small ({a.shape[1]} x {a.shape[0]} px)")
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"{name} must hold real grey levels, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite grey levels")
    return a


def check_not_blank(image: np.ndarray, name: str, min_std: float = 0.5) -> None:
    """Reject an image with (almost) no contrast: grey-level std below ``min_std``."""
    s = float(np.std(image))
    if s < min_std:
        raise ValueError(
            f"{name} is blank: grey-level standard deviation {s:.3g} < {min_std:g} "
            "(no speckle pattern to correlate)"
        )


def grid_points(shape: tuple[int, int], subset: int, step: int, roi=None) -> np.ndarray:
    """Subset centres (n, 2) as (x, y) on a regular grid inside ``roi``.

    roi : (x0, y0, x1, y1) pixel bounds, half-open like slicing (x0 <= x < x1), or None for the
          whole image. Subsets lie entirely inside the ROI; the grid is centred in it.
    """
    rows, cols = shape
    if roi is None:
        roi = (0, 0, cols, rows)
    try:
        x0, y0, x1, y1 = (int(v) for v in roi)
    except (TypeError, ValueError):
        raise ValueError(f"ROI {roi!r} must be four integers X0,Y0,X1,Y1") from None
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"ROI {roi!r} is empty: need X1 > X0 and Y1 > Y0")
    if x0 < 0 or y0 < 0 or x1 > cols or y1 > rows:
        raise ValueError(
            f"ROI ({x0},{y0},{x1},{y1}) lies (partly) outside the image ({cols} x {rows} px; "
            f"valid bounds 0 <= X0 < X1 <= {cols}, 0 <= Y0 < Y1 <= {rows})"
        )
    if subset > x1 - x0 or subset > y1 - y0:
        raise ValueError(
            f"subset of {subset} x {subset} px is larger than the ROI ({x1 - x0} x {y1 - y0} px)"
        )
    h = subset // 2
    xs = np.arange(x0 + h, x1 - h, step)
    ys = np.arange(y0 + h, y1 - h, step)
    # centre the grid in the ROI
    xs = xs + ((x1 - h - 1) - xs[-1]) // 2
    ys = ys + ((y1 - h - 1) - ys[-1]) // 2
    X, Y = np.meshgrid(xs, ys)
    return np.column_stack([X.ravel(), Y.ravel()]).astype(float)


# --------------------------------------------------------------------------- warps


def _matrices(p: np.ndarray) -> np.ndarray:
    """(k, 6) shape parameters -> (k, 3, 3) warp matrices."""
    M = np.zeros((len(p), 3, 3))
    M[:, 0, 0] = 1 + p[:, 1]
    M[:, 0, 1] = p[:, 2]
    M[:, 0, 2] = p[:, 0]
    M[:, 1, 0] = p[:, 4]
    M[:, 1, 1] = 1 + p[:, 5]
    M[:, 1, 2] = p[:, 3]
    M[:, 2, 2] = 1.0
    return M


def _params(M: np.ndarray) -> np.ndarray:
    return np.column_stack(
        [M[:, 0, 2], M[:, 0, 0] - 1, M[:, 0, 1], M[:, 1, 2], M[:, 1, 0], M[:, 1, 1] - 1]
    )


def _inverse_warp(dp: np.ndarray) -> np.ndarray:
    """(k, 3, 3) inverse of the warp matrices of increments ``dp``."""
    a, b, c = 1 + dp[:, 1], dp[:, 2], dp[:, 0]
    d, e, f = dp[:, 4], 1 + dp[:, 5], dp[:, 3]
    det = a * e - b * d
    Mi = np.zeros((len(dp), 3, 3))
    Mi[:, 0, 0] = e / det
    Mi[:, 0, 1] = -b / det
    Mi[:, 0, 2] = (b * f - c * e) / det
    Mi[:, 1, 0] = -d / det
    Mi[:, 1, 1] = a / det
    Mi[:, 1, 2] = (c * d - a * f) / det
    Mi[:, 2, 2] = 1.0
    return Mi


def transfer(p: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Carry warps ``p`` (k, 6) over offsets ``d`` (k, 2) = new centre - old centre."""
    q = p.copy()
    q[:, 0] += p[:, 1] * d[:, 0] + p[:, 2] * d[:, 1]
    q[:, 3] += p[:, 4] * d[:, 0] + p[:, 5] * d[:, 1]
    return q


# --------------------------------------------------------------------------- correlator


class Correlator:
    """IC-GN subset correlation of deformed images against one reference image.

    reference : 2-D grey-level image
    points    : (n, 2) subset centres (x, y) in px; rounded to the nearest pixel
    config    : :class:`DICConfig`

    All reference-side quantities (subset grey levels, gradients, Hessians and their inverses)
    are computed once here and reused for every deformed image.
    """

    def __init__(self, reference: np.ndarray, points: np.ndarray, config: DICConfig = DICConfig()):
        self.config = config
        self._step = get_step(config.backend)
        ref = as_grey(reference, "reference image")
        check_not_blank(ref, "reference image")
        self.reference = ref
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            raise ValueError("no points to correlate")
        c = np.rint(pts).astype(np.int64)
        h = config.half
        rows, cols = ref.shape
        if config.subset > min(rows, cols):
            raise ValueError(
                f"subset of {config.subset} px is larger than the image ({cols} x {rows} px)"
            )
        bad = (
            (c[:, 0] - h < 0)
            | (c[:, 1] - h < 0)
            | (c[:, 0] + h > cols - 1)
            | (c[:, 1] + h > rows - 1)
        )
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"{int(bad.sum())} subset(s) of {config.subset} px do not fit in the {cols} x "
                f"{rows} px image, e.g. the one centred at ({c[k, 0]}, {c[k, 1]})"
            )
        self.cx, self.cy = c[:, 0], c[:, 1]
        self.points = c.astype(float)
        self.n = len(c)
        r = np.arange(-h, h + 1)
        dy, dx = np.meshgrid(r, r, indexing="ij")
        self.dx, self.dy = dx.ravel().astype(float), dy.ravel().astype(float)
        self.P = self.dx.size
        self.Xi = np.column_stack([np.ones(self.P), self.dx, self.dy])  # (P, 3)
        self._prepare_reference()
        self.neighbours = neighbour_graph(self.points)

    # -- reference side ----------------------------------------------------------------

    def _prepare_reference(self) -> None:
        cfg = self.config
        spline = BSplineImage(self.reference, cfg.order)
        gx, gy = spline.gradient_at_pixels()
        cols = self.reference.shape[1]
        flat = (self.cy[:, None] + self.dy[None, :].astype(np.int64)) * cols + (
            self.cx[:, None] + self.dx[None, :].astype(np.int64)
        )
        f = self.reference.ravel()[flat]
        self.f0 = f - f.mean(axis=1, keepdims=True)
        self.df = np.sqrt(np.sum(self.f0**2, axis=1))
        self.fx = gx.ravel()[flat]
        self.fy = gy.ravel()[flat]
        Xi2 = (self.Xi[:, :, None] * self.Xi[:, None, :]).reshape(self.P, 9)
        H = np.zeros((self.n, 6, 6))
        H[:, :3, :3] = ((self.fx * self.fx) @ Xi2).reshape(-1, 3, 3)
        H[:, :3, 3:] = ((self.fx * self.fy) @ Xi2).reshape(-1, 3, 3)
        H[:, 3:, :3] = H[:, :3, 3:].transpose(0, 2, 1)
        H[:, 3:, 3:] = ((self.fy * self.fy) @ Xi2).reshape(-1, 3, 3)
        self.H = H
        texture = self.df / np.sqrt(self.P) >= cfg.min_texture
        # scale the shape-gradient rows so the conditioning check is unit-independent
        s = np.array([1, self.config.half, self.config.half] * 2, dtype=float)
        Hs = H / s[None, :, None] / s[None, None, :]
        ev = np.linalg.eigvalsh(Hs)
        wellposed = ev[:, 0] > 1e-8 * np.maximum(ev[:, -1], 1e-300)
        self.valid = texture & wellposed
        Hinv = np.full_like(H, np.nan)
        if np.any(self.valid):
            Hinv[self.valid] = np.linalg.inv(H[self.valid])
        self.Hinv = Hinv

    # -- IC-GN -------------------------------------------------------------------------

    def icgn(self, spline: BSplineImage, idx: np.ndarray, p0: np.ndarray):
        """Run IC-GN for subsets ``idx`` from warps ``p0`` (k, 6).

        Returns ``(p, zncc, iterations, ok, s2)``: final warps, ZNCC at the last evaluation,
        iterations used, convergence (|dp| < tol, image not left, ZNCC >= zncc_min) and the
        residual variance ``sum r^2 / (P - 8)``.
        """
        idx = np.asarray(idx, dtype=np.int64)
        k = len(idx)
        p = np.array(p0, dtype=float).reshape(k, 6)
        zncc = np.full(k, np.nan)
        iters = np.zeros(k, dtype=np.int64)
        ok = np.zeros(k, dtype=bool)
        s2 = np.full(k, np.nan)
        for s in range(0, k, self.config.chunk):
            sl = slice(s, min(k, s + self.config.chunk))
            p[sl], zncc[sl], iters[sl], ok[sl], s2[sl] = self._icgn_chunk(spline, idx[sl], p[sl])
        return p, zncc, iters, ok, s2

    def _icgn_chunk(self, spline: BSplineImage, idx: np.ndarray, p0: np.ndarray):
        cfg = self.config
        h = cfg.half
        k = len(idx)
        M = _matrices(p0)
        zncc = np.full(k, np.nan)
        iters = np.zeros(k, dtype=np.int64)
        ok = np.zeros(k, dtype=bool)
        s2 = np.full(k, np.nan)
        act = np.flatnonzero(self.valid[idx])  # positions (into idx) still iterating
        start = p0[:, [0, 3]].copy()
        for it in range(1, cfg.max_iter + 1):
            if act.size == 0:
                break
            gi = idx[act]
            A = M[act]
            b, rr, dg, inside = self._step(
                spline, self.cx, self.cy, gi, A, self.Xi, self.f0, self.fx, self.fy, self.df
            )
            good = inside & (dg > 0) & np.all(np.isfinite(b), axis=1)
            dp = -np.einsum("kij,kj->ki", self.Hinv[gi], b)
            M[act] = A @ _inverse_warp(dp)
            iters[act] = it
            zncc[act] = np.where(good, 1.0 - 0.5 * rr / self.df[gi] ** 2, np.nan)
            s2[act] = rr / max(self.P - 8, 1)
            norm = np.sqrt(
                dp[:, 0] ** 2 + dp[:, 3] ** 2 + h * h * np.sum(dp[:, [1, 2, 4, 5]] ** 2, axis=1)
            )
            moved = np.hypot(M[act, 0, 2] - start[act, 0], M[act, 1, 2] - start[act, 1])
            diverged = ~good | ~np.isfinite(norm) | (moved > cfg.subset)
            done = ~diverged & (norm < cfg.tol)
            ok[act[done]] = True
            act = act[~(done | diverged)]
        p = _params(M)
        ok &= zncc >= cfg.zncc_min
        return p, zncc, iters, ok, s2

    # -- driver ------------------------------------------------------------------------

    def correlate(self, deformed: np.ndarray, initial: DICResult | None = None) -> DICResult:
        """Correlate one deformed image (same size as the reference).

        initial : a previous snapshot's result at the same points; its converged warps are the
                  starting guesses (the others are filled in by propagation). None: FFT seeds
                  and reliability-guided propagation over the whole point set.
        """
        cfg = self.config
        g = as_grey(deformed, "deformed image")
        if g.shape != self.reference.shape:
            raise ValueError(
                f"image sizes differ: reference is {self.reference.shape[1]} x "
                f"{self.reference.shape[0]} px, deformed is {g.shape[1]} x {g.shape[0]} px"
            )
        check_not_blank(g, "deformed image")
        spline = BSplineImage(g, cfg.order)
        n = self.n
        p = np.zeros((n, 6))
        zncc = np.full(n, np.nan)
        iters = np.zeros(n, dtype=np.int64)
        done = np.zeros(n, dtype=bool)
        s2 = np.full(n, np.nan)
        tries = np.zeros(n, dtype=np.int64)
        stats = {"seeds": 0, "rounds": 0, "from_initial": 0}

        def run(sel: np.ndarray, p0: np.ndarray) -> None:
            q, z, it, c, v = self.icgn(spline, sel, p0)
            p[sel], zncc[sel], iters[sel], done[sel], s2[sel] = q, z, it, c, v

        if initial is not None:
            if len(initial.params) != n:
                raise ValueError("the initial result was computed at different points")
            sel = np.flatnonzero(initial.converged & self.valid)
            if sel.size:
                run(sel, initial.params[sel])
                stats["from_initial"] = int(done.sum())
        if not np.any(done):
            stats["seeds"] = self._seed(g, spline, p, zncc, iters, done, s2, tries, run)
        for _attempt in range(3):
            stats["rounds"] += self._propagate(p, zncc, done, tries, run)
            rest = self.valid & ~done & (tries == 0)
            if not np.any(rest):
                break
            # unreached points (e.g. a separate region): seed again among them
            stats["seeds"] += self._seed(
                g, spline, p, zncc, iters, done, s2, tries, run, among=rest
            )

        cov = np.full((n, 6, 6), np.nan)
        if cfg.noise_sigma is None:
            # residual variance = sigma_f^2 + gamma sigma_g^2 (interpolation averages the noise
            # of g), while the displacement noise sees the full sigma_g^2: Var(p) = 2 sigma^2 H^-1
            gam = noise_gain(p[:, 0], cfg.order) * noise_gain(p[:, 3], cfg.order)
            var = 2.0 * s2 / (1.0 + gam)
        else:
            var = np.full(n, 2.0 * cfg.noise_sigma**2)
        cov[done] = var[done, None, None] * self.Hinv[done]
        params = np.where(done[:, None], p, np.nan)
        sig = float(np.sqrt(np.median(var[done]) / 2.0)) if np.any(done) else float("nan")
        return DICResult(
            x=self.points[:, 0].copy(),
            y=self.points[:, 1].copy(),
            params=params,
            zncc=zncc,
            iterations=iters,
            converged=done.copy(),
            cov=cov,
            noise_sigma=sig,
            meta=stats,
        )

    def _seed(self, g, spline, p, zncc, iters, done, s2, tries, run, among=None) -> int:
        """FFT integer guesses + IC-GN at seed points; returns how many seeds converged."""
        cfg = self.config
        pool = self.valid if among is None else among
        cands = seed_candidates(self.points, pool, cfg.n_seeds)
        extra = np.flatnonzero(pool & ~np.isin(np.arange(self.n), cands))
        rng = np.random.default_rng(12345)
        extra = list(rng.permutation(extra)[:20])
        half = cfg.seed_subset // 2 if cfg.seed_subset else cfg.subset
        good = 0
        for batch in (cands, extra):
            if not batch:
                continue
            p0 = np.zeros((len(batch), 6))
            for j, i in enumerate(batch):
                du, dv, _ = integer_guess(
                    self.reference, g, int(self.cx[i]), int(self.cy[i]), half, cfg.search_radius
                )
                p0[j, 0], p0[j, 3] = du, dv
            sel = np.asarray(batch, dtype=np.int64)
            run(sel, p0)
            tries[sel] += 1
            good += int(done[sel].sum())
            if good:
                break
        return good

    def _propagate(self, p, zncc, done, tries, run) -> int:
        """Reliability-guided propagation in rounds; returns the number of rounds."""
        cfg = self.config
        nb = self.neighbours
        has = nb >= 0
        last_src = -np.ones(self.n, dtype=np.int64)
        rounds = 0
        while True:
            nz = np.where(has & done[np.where(has, nb, 0)], zncc[np.where(has, nb, 0)], -np.inf)
            best = np.argmax(nz, axis=1)
            bestz = nz[np.arange(self.n), best]
            src = nb[np.arange(self.n), best]
            cand = (
                self.valid
                & ~done
                & np.isfinite(bestz)
                & (tries < cfg.max_tries)
                & (src != last_src)
            )
            if not np.any(cand):
                return rounds
            sel = np.flatnonzero(cand)
            s = src[sel]
            p0 = transfer(p[s], self.points[sel] - self.points[s])
            run(sel, p0)
            tries[sel] += 1
            last_src[sel] = s
            rounds += 1
