"""The wave model's Jacobian on the aperture grid: delta (N x N) -> intensity on the sphere.

Frame and units (docs/physics.md): the aperture grid of :mod:`solver.aperture` (x, y, delta
in m), the scan's sphere grid (theta, phi in rad) about the focus; intensities relative to
the incident wave.

The refinement's PO model (:class:`solver.forward.WaveForward`) sees a surface estimate as
``GriddedMap(x, y, extend_outside(grid, delta))``: the values inside the aperture, continued
outside by their local quadratic near the rim and a discrete Laplace equation beyond
(:class:`solver.continuation.RimContinuation`, whose
:meth:`~solver.continuation.RimContinuation.transpose` is the continuation's adjoint), then the
bicubic interpolating spline of FITPACK (scipy's RectBivariateSpline, s = 0), which clamps
points beyond the outer grid centres to them. Every step is linear in delta, so
:class:`GridToSamples` writes the map from the grid values inside the aperture to (dz, dh/dx,
dh/dy) at the PO samples, and its transpose, with the spline's own knots: the B-spline
coefficients are Ay^-1 Z Ax^-T (collocation matrices at the grid centres), the sample values
B_y(y_s) C B_x(x_s)^T and the slopes with one factor differentiated. With
:mod:`raysim.optics.po_jacobian` this gives the model's exact JVP and VJP
(:class:`WaveJacobian`): dI = 2 Re(conj(E) . dE) per sphere cell, or with a polarised probe
(:mod:`raysim.maps.probe`: I = |v . E|^2, v = sqrt(g(0)) p_t real) dI = 2 Re(conj(v . E) v . dE).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.interpolate import BSpline, RectBivariateSpline

from raysim.maps.sphere import SphereGrid
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import Targets
from solver.aperture import ApertureGrid
from solver.errors import SolverError
from solver.forward import WaveForward
from solver.nonlinear import extend_outside, outside_fill

DEGREE = 3
CHUNK = 65_536
#: the fast radiator's tolerance for the Jacobian's products, at its loosest: Gauss-Newton's
#: truncated LSQR solves a step to about 1e-2, so products to 1e-4 leave the steps as they
#: are, while the fields (the misfit the steps are judged by) keep the model's own tolerance
JACOBIAN_TOL = 1e-4
#: memory the Jacobian holds per PO sample of the model's reflector (bytes): its surface
#: elements (the moment and its three derivatives, 508 bytes a sample at 1 GHz on the paper's
#: dish, measured as resident memory) and the grid-to-samples matrices (200), with some room;
#: unlike the forward sum, which holds a batch of samples, the Jacobian holds them all
JACOBIAN_BYTES_PER_SAMPLE = 800.0


def _basis(x: NDArray[np.float64], t: NDArray[np.float64], lo: float, hi: float):
    """Sparse (n, n_coef) values and first derivatives of the degree-3 B-splines on knots t
    at x clamped to [lo, hi] (FITPACK's rule for points beyond the data)."""
    xc = np.clip(x, lo, hi)
    B = BSpline.design_matrix(xc, t, DEGREE).tocsr()
    # degree 2 on the same knots, at the last knot from the left (the slope is continuous;
    # the degree-2 functions there would be read on the empty interval beyond it)
    low = BSpline.design_matrix(np.minimum(xc, np.nextafter(hi, lo)), t, DEGREE - 1).tocsr()
    n = len(t) - DEGREE - 1
    i = np.arange(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        left = np.where(t[i + DEGREE] > t[i], DEGREE / (t[i + DEGREE] - t[i]), 0.0)
        right = np.where(t[i + DEGREE + 1] > t[i + 1],
                         DEGREE / (t[i + DEGREE + 1] - t[i + 1]), 0.0)
    # d/dx B_i,3 = 3 B_i,2 / (t_i+3 - t_i) - 3 B_i+1,2 / (t_i+4 - t_i+1)
    M = sp.diags([left, -right], [0, -1], shape=(n + 1, n)).tocsr()
    return B, (low @ M).tocsr()


@dataclass
class GridToSamples:
    """The linear map grid values inside the aperture -> (dz, dh_x, dh_y) at points (x_s, y_s).

    ``grid`` the aperture grid; ``x``, ``y`` (n,) the sample footprints (m).
    """

    grid: ApertureGrid
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    _cache: dict = field(default_factory=dict, repr=False)

    @cached_property
    def _spline(self):
        g = self.grid
        probe = RectBivariateSpline(g.y, g.x, np.zeros((g.N, g.N)), kx=DEGREE, ky=DEGREE, s=0)
        ty, tx = probe.get_knots()
        Ay = BSpline.design_matrix(g.y, ty, DEGREE).toarray()
        Ax = BSpline.design_matrix(g.x, tx, DEGREE).toarray()
        By, dBy = _basis(self.y, ty, g.y[0], g.y[-1])
        Bx, dBx = _basis(self.x, tx, g.x[0], g.x[-1])
        return np.linalg.inv(Ay), np.linalg.inv(Ax), By, dBy, Bx, dBx

    def _filled(self, delta_in: NDArray[np.float64]) -> NDArray[np.float64]:
        """The grid values inside the aperture continued outside it (:func:`extend_outside`)."""
        g = self.grid
        Z = np.zeros((g.N, g.N))
        Z[g.mask] = delta_in
        return extend_outside(g, Z)

    def _filled_T(self, G: NDArray[np.float64]) -> NDArray[np.float64]:
        """The adjoint of :meth:`_filled`: a gradient on the whole grid -> on the values inside."""
        g = self.grid
        return outside_fill(float(g.D), int(g.N)).transpose(G)[g.mask]

    def apply(self, delta_in: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
        """(dz, dh_x, dh_y) at the samples for grid values ``delta_in`` (m, inside the mask)."""
        iAy, iAx, By, dBy, Bx, dBx = self._spline
        C = iAy @ self._filled(delta_in) @ iAx.T
        dz, hx, hy = (np.empty(len(self.x)) for _ in range(3))
        for lo in range(0, len(self.x), CHUNK):
            s = slice(lo, lo + CHUNK)
            YC = By[s] @ C
            dz[s] = np.asarray(Bx[s].multiply(YC).sum(axis=1)).ravel()
            hx[s] = np.asarray(dBx[s].multiply(YC).sum(axis=1)).ravel()
            hy[s] = np.asarray(Bx[s].multiply(dBy[s] @ C).sum(axis=1)).ravel()
        return dz, hx, hy

    def transpose(self, g_z, g_x, g_y) -> NDArray[np.float64]:
        """The adjoint: per-sample gradients in (dz, dh_x, dh_y) -> gradient on the grid values."""
        iAy, iAx, By, dBy, Bx, dBx = self._spline
        GC = (By.T @ sp.diags(g_z) @ Bx + By.T @ sp.diags(g_x) @ dBx
              + dBy.T @ sp.diags(g_y) @ Bx).toarray()
        return self._filled_T(iAy.T @ GC @ iAx)


def _check_memory(reflector: Reflector, wavelength: float, samples_per_wavelength: float,
                  targets: Targets | None = None) -> None:
    """Refuse (SolverError, one line) a Jacobian whose samples would not fit this machine's
    memory (:data:`JACOBIAN_BYTES_PER_SAMPLE` each above ``simulate``'s base), before the
    model's field is computed."""
    from raysim.simulate import WAVE_BASE_BYTES, physical_memory
    from raysim.surface.quadrature import plan

    n = plan(reflector, wavelength, samples_per_wavelength, targets).n_samples
    need = WAVE_BASE_BYTES + JACOBIAN_BYTES_PER_SAMPLE * n
    if need > physical_memory():
        raise SolverError(f"Gauss-Newton's Jacobian needs {n:.2g} PO samples, about {need / 1e9:.2g} GB, "
                          f"more than this machine's {physical_memory() / 1e9:.3g} GB: use the "
                          "defect correction (--refine-method defect) or a lower frequency")


class WaveJacobian:
    """The PO (+ PTD) model's intensity and its exact linearisation at one surface estimate.

    ``model`` a :class:`solver.forward.WaveForward` (PO or PO + PTD, in this process);
    ``delta`` (N, N) the estimate (m, NaN outside the aperture) on ``grid``; ``sphere``, ``F``,
    ``D`` the scan (m). Takes the model's reflector and complex field E at the cell centres
    (:meth:`solver.forward.WaveForward.field`: :attr:`intensity` is the model's intensity),
    and the PO samples and rim points of that reflector under the model's wave. :meth:`jvp`
    maps a grid perturbation (values inside the aperture, m) to dI on the sphere, :meth:`vjp`
    the transpose.
    """

    def __init__(self, model: WaveForward, sphere: SphereGrid, F: float, D: float,
                 grid: ApertureGrid, delta: NDArray[np.float64]) -> None:
        from raysim.optics import po, po_jacobian
        from raysim.surface.quadrature import targets_around

        self.model, self.sphere, self.grid = model, sphere, grid
        self.points = sphere.points(F).reshape(-1, 3)
        self.focus = (0.0, 0.0, float(F))  # the sphere's centre: the fast radiator's chart
        self.shape = (sphere.n_theta, sphere.n_phi)
        surface = (grid.x, grid.y, extend_outside(grid, delta))
        self.wave = model.job(sphere, F, D, surface).wave()
        spw = po.DEFAULT_SAMPLES_PER_WAVELENGTH if model.samples_per_wavelength is None \
            else model.samples_per_wavelength
        # the model's own reflector and field (PO, PTD's rim, the incident wave when total)
        self.reflector = model.reflector(D, F, surface)
        # the forward model's quadrature (its points set it: solver.forward.WaveForward.build)
        targets = targets_around(self.points, self.focus, self.wave.k_hat)
        _check_memory(self.reflector, self.wave.wavelength, spw, targets)
        self.E = model.field(sphere, F, D, surface).reshape(-1, 3)
        self.elements = po_jacobian.surface_elements(self.reflector, self.wave, spw, model.device, targets)
        self.samples = GridToSamples(grid, self.elements.x, self.elements.y)
        # the probe as a real vector per point (None: |E|^2 times the boresight pattern g0)
        from raysim.maps.probe import arrival_directions

        self.v = None if model.probe.ideal else model.probe.vector(
            arrival_directions(sphere.directions().reshape(-1, 3)))
        self.g0 = float(model.probe.pattern(0.0))
        self.edges = None
        if model.ptd:
            from raysim.optics import ptd_jacobian

            self.edges = ptd_jacobian.edge_state(self.reflector, self.wave, "rim",
                                                 device=model.device)
            self.edge_samples = GridToSamples(grid, self.edges.x, self.edges.y)
        self.calls = {"jvp": 0, "vjp": 0}
        self.cells: NDArray[np.bool_] | None = None

    def restrict(self, cells: NDArray[np.bool_] | None) -> None:
        """Evaluate :meth:`jvp` and :meth:`vjp` on the sphere cells ``cells`` only
        ((n_theta, n_phi) boolean; None: all): each product then costs that fraction of a
        radiation. The JVP is zero on the other cells and the VJP ignores their weights, so
        the pair stays each other's transpose (the Jacobian's rows on ``cells``)."""
        self.cells = None if cells is None else np.asarray(cells, dtype=bool).reshape(-1)

    def _at(self, a: NDArray | None) -> NDArray | None:
        """The rows of a per-point array on the evaluated cells."""
        return a if a is None or self.cells is None else a[self.cells]

    @property
    def intensity(self) -> NDArray[np.float64]:
        """What the model's probe reads (n_theta, n_phi) at this estimate: |E|^2 for the
        ideal meter."""
        if self.v is None:
            return (self.g0 * np.sum(np.abs(self.E) ** 2, axis=-1)).reshape(self.shape)
        return (np.abs(np.sum(self.v * self.E, axis=-1)) ** 2).reshape(self.shape)

    def _reading(self) -> NDArray[np.complex128]:
        """The vector c (evaluated points, 3) with dI = 2 Re(conj(c) . dE): g0 E, or
        (v . E) v."""
        E, v = self._at(self.E), self._at(self.v)
        if v is None:
            return E if self.g0 == 1.0 else self.g0 * E
        return np.sum(v * E, axis=-1, keepdims=True) * v

    @property
    def _fast(self) -> dict:
        """How the products sum their elements: the model's radiator, at the looser of its
        tolerance and :data:`JACOBIAN_TOL`."""
        return {"radiator": self.model.radiator, "tol": max(self.model.radiator_tol, JACOBIAN_TOL),
                "centre": self.focus}

    def field_jvp(self, v_in: NDArray[np.float64]) -> NDArray[np.complex128]:
        """dE (evaluated points, 3) for grid values ``v_in`` (m) inside the aperture."""
        from raysim.optics import po_jacobian

        points = self._at(self.points)
        dz, hx, hy = self.samples.apply(v_in)
        fast = self._fast
        dE = po_jacobian.jvp(self.elements, points, dz, hx, hy, self.model.device, **fast)
        if self.edges is not None:
            from raysim.optics import ptd_jacobian

            dE = dE + ptd_jacobian.jvp(self.edges, self.wave, points, *self.edge_samples.apply(v_in),
                                       device=self.model.device, **fast)
        return dE

    def jvp(self, v_in: NDArray[np.float64]) -> NDArray[np.float64]:
        """dI (n_theta, n_phi) = 2 Re(conj(E) . dE) (with a probe: of its reading, module
        docstring) for grid values ``v_in`` (m); zero off the evaluated cells."""
        self.calls["jvp"] += 1
        dE = self.field_jvp(v_in)
        dI = 2.0 * np.real(np.sum(np.conj(self._reading()) * dE, axis=-1))
        if self.cells is None:
            return dI.reshape(self.shape)
        out = np.zeros(self.cells.shape)
        out[self.cells] = dI
        return out.reshape(self.shape)

    def vjp(self, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """The transpose: weights ``y`` (n_theta, n_phi) on dI -> gradient on the grid values
        (the weights off the evaluated cells are not read)."""
        from raysim.optics import po_jacobian

        self.calls["vjp"] += 1
        weights = self._at(np.asarray(y, dtype=np.float64).reshape(-1))
        c = 2.0 * weights[:, None] * self._reading()
        points = self._at(self.points)
        fast = self._fast
        g = po_jacobian.vjp(self.elements, points, c, self.model.device, **fast)
        out = self.samples.transpose(*g)
        if self.edges is not None:
            from raysim.optics import ptd_jacobian

            g = ptd_jacobian.vjp(self.edges, self.wave, points, c, self.model.device, **fast)
            out = out + self.edge_samples.transpose(*g)
        return out
