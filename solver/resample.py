"""Sphere (theta, phi) samples -> the aperture grid (x, y) through the ideal GO mapping.

Frame (docs/physics.md): theta from -z at the focus, phi = atan2(y, x), both in rad, on a regular
cell-centre grid (:class:`raysim.maps.sphere.SphereGrid`); the aperture point (x, y) (m) sees the
sphere at theta = 2 atan(r / 2F), phi = atan2(y, x) (paper Eq. 34).

Steps, each stated in the result so a reader knows what was done to the data:

1. usable rows: sphere cells whose theta range lies wholly inside the rim image
   theta_rim = 2 atan(D / 4F); the cell the rim cuts holds part-lit power and is not used;
2. missing samples (NaN) inside the usable rows are filled by smooth inpainting on the
   (theta, phi) grid (least-squares Laplacian over the holes, periodic in phi);
3. rows between the last usable one and the rim are continued by the cubic in theta through
   the last four usable rows;
4. a cubic spline in (theta, phi), periodic in phi and continued across the pole (theta -> -theta
   is phi -> phi + pi), gives the values at the aperture points inside the disk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates

from raysim.errors import FieldMapError
from raysim.maps.sphere import SphereGrid, aperture_radius, theta_rim
from solver.aperture import ApertureGrid

PAD = 8             # cells of padding around the spline's array
EXTRA_ROWS = 6      # rows extrapolated past the last usable one
MAX_GAP_CELLS = 3   # how far (in cells) the last usable row may stop short of the rim
#: the share of the rim's radius beyond the last usable row's centre above which the map says
#: that ring is extrapolated, not measured (4.5 deg rows stopping at 54 deg on a rim image at
#: 64 deg left 22 % of the radius, a third of the dish, and a bump there read with the wrong
#: sign, without a word; the campaign's coarse 5 deg rows on the 110 m dish leave 12 %)
RING_SHARE_WARNING = 0.15


@dataclass(frozen=True)
class Coverage:
    """What the sphere data cover: usable rows, filled holes, extrapolated band (rad)."""

    n_rows: int
    theta_last: float
    n_filled: int
    theta_rim: float


def usable_rows(sphere: SphereGrid, F: float, D: float) -> int:
    """Number of leading theta rows whose cells lie wholly inside the rim image."""
    edges_hi = sphere.theta_edges[1:]
    n = int(np.count_nonzero(edges_hi <= theta_rim(D, F) + 1e-12))
    if n < 4:
        raise FieldMapError("the scan has fewer than four theta rows inside the rim image")
    if theta_rim(D, F) - sphere.theta[n - 1] > MAX_GAP_CELLS * sphere.dtheta:
        raise FieldMapError(
            f"the scan stops at theta = {np.degrees(sphere.theta_max):.2f} deg, short of the "
            f"rim image at {np.degrees(theta_rim(D, F)):.2f} deg")
    return n


def unmeasured_ring(sphere: SphereGrid, F: float, D: float) -> tuple[float, float]:
    """(share of the rim's radius, aperture radius in m) the scan's last usable row's centre
    leaves to the rim: the ring the spline extrapolates rather than interpolates."""
    reached = float(aperture_radius(sphere.theta[usable_rows(sphere, F, D) - 1], F))
    return max(1.0 - 2.0 * reached / D, 0.0), reached


#: the spacing on the dish of the scan's usable cells, as shares of D, above which the map is
#: said not to resolve the surface: radially between rows, and round the rim between columns.
#: Exact GO cell means of the paper's surface, inverted: rows 2.75 m apart gave 0.6 % RRMS,
#: 4.3 m 90 %, 6.3 m 52 %, 7.7 m 520 % (the FA is the surface's Laplacian, and rows too far
#: apart alias its radial ripple); columns 9.6 m apart at the rim gave 0.3 %. Twelve 5 m
#: bumps over the dish: 0.3 % with columns 9.6 m apart at the rim, 1.8 % at 14.4 m, 4.5 % at
#: 28.8 m. The rig rehearsal's 10 x 30 deg cells, 8.6 m and 29 m apart, missed the paper's
#: surface by 4.5 times its peak-to-peak, noise-free
SAMPLING_RADIAL_SHARE = 1.0 / 32.0
SAMPLING_RIM_SHARE = 1.0 / 8.0


def cell_spacing(sphere: SphereGrid, F: float, D: float) -> tuple[float, float]:
    """(radial, round the rim) spacing (m) on the dish of the scan's usable cells: the largest
    step between the aperture radii of consecutive usable rows' centres (the pole's for the
    first), and the rim's arc of one phi step."""
    n = usable_rows(sphere, F, D)
    radii = aperture_radius(np.concatenate([[0.0], sphere.theta[:n]]), F)
    return float(np.max(np.diff(radii))), 0.5 * D * float(sphere.dphi)


def modelled_rows(sphere: SphereGrid, F: float, D: float, h: float) -> int:
    """The usable rows (:func:`usable_rows`) whose cells' rays all meet the dish inside the
    outermost centres of an aperture grid of step ``h`` (m), half a step inside the rim (the
    ideal GO mapping), and never fewer than four: the rows a forward model of the map on that
    grid can be compared with.

    Beyond those centres, on the axes, the model's spline of the grid values holds the last
    one's value. A row whose outer edge meets the rim image (2 deg rows on a dish of F/D = 0.4
    end 0.01 deg inside it) takes rays from there: on a 50 m dish the exact Z(20, 10) surface,
    sampled on the grid, missed that row's FA by 38 % of the data's RMS, and the refinement
    fitted the difference into the map (37.6 um of error; 29.9 um without the row). A whole
    step's margin dropped rows the model holds on coarse grids: the paper's case on 2 deg
    rows at N = 64 went from 3.4 to 4.6 um.
    """
    n = usable_rows(sphere, F, D)
    outer = aperture_radius(sphere.theta_edges[1:n + 1], F)
    return max(int(np.count_nonzero(outer <= 0.5 * (D - h))), min(n, 4))


def check_full_circle(sphere: SphereGrid) -> None:
    """The aperture needs every azimuth: raise unless the phi cells close around the axis."""
    if not sphere.full_circle:
        raise FieldMapError("the scan must cover the full circle in phi (0..360 deg)")


#: the largest hole (connected missing cells, not hidden by an obstacle) the inversion fills,
#: as a share of the usable cells: beyond it the scan is refused (half the azimuths missing
#: came back 108 % off, with exit 0); above HOLE_SHARE_WARNING the SurfaceMap says so
MAX_HOLE_SHARE = 0.1
HOLE_SHARE_WARNING = 0.01


@dataclass(frozen=True)
class Hole:
    """The largest connected set of missing cells in the usable rows: its share of them and its
    extent in theta and phi (deg, cell edges; phi may wrap through 360)."""

    share: float
    theta_deg: tuple[float, float]
    phi_deg: tuple[float, float]

    def describe(self) -> str:
        return (f"{self.share * 100:.1f} % of the cells inside the rim image, theta "
                f"{self.theta_deg[0]:.1f}..{self.theta_deg[1]:.1f} deg, phi "
                f"{self.phi_deg[0]:.1f}..{self.phi_deg[1]:.1f} deg")


def largest_hole(missing: NDArray[np.bool_], sphere: SphereGrid) -> Hole | None:
    """The largest hole of the ``missing`` cells (n_rows, n_phi; neighbours along theta and phi,
    periodic in phi on a full circle), or None without any."""
    from scipy.ndimage import label

    labels, n = label(missing)
    if n == 0:
        return None
    if sphere.full_circle:  # a hole across phi = 0 is one hole
        for a, b in zip(labels[:, 0], labels[:, -1], strict=True):
            if a and b and a != b:
                labels[labels == b] = a
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    rows, cols = np.nonzero(labels == int(np.argmax(sizes)))
    edges_t, edges_p = np.degrees(sphere.theta_edges), np.degrees(sphere.phi_edges)
    used = np.unique(cols)
    gaps = np.diff(np.concatenate([used, [used[0] + sphere.n_phi]]))
    start = (int(used[(int(np.argmax(gaps)) + 1) % used.size])
             if sphere.full_circle and used.size < sphere.n_phi else int(used[0]))
    span = sphere.n_phi - int(gaps.max()) + 1 if sphere.full_circle else int(used[-1] - used[0]) + 1
    phi_lo = float(edges_p[start])
    return Hole(float(rows.size / missing.size), (float(edges_t[rows.min()]),
                                                   float(edges_t[rows.max() + 1])),
                (phi_lo, phi_lo + span * float(np.degrees(sphere.dphi))))


def fill_missing(values: NDArray[np.float64], n_rows: int,
                 pole: bool = True) -> tuple[NDArray[np.float64], int]:
    """Fill NaN samples of the first ``n_rows`` rows so the field's Laplacian is least there.

    The hole values minimise the sum of squares of the 5-point (theta, phi) Laplacian over
    every stencil that touches a hole (a discrete biharmonic fill, exact for discrete-harmonic
    fields; the last row uses a one-sided theta difference). Periodic in phi; with ``pole``
    (row 0 half a step from the pole) the theta neighbour of row 0 at phi is row 0 at
    phi + pi, else row 0 has no stencil of its own. Returns the filled copy and the number of
    samples filled.
    """
    out = np.array(values, dtype=np.float64, copy=True)
    block = out[:n_rows]
    holes = ~np.isfinite(block)
    n_holes = int(np.count_nonzero(holes))
    if n_holes == 0:
        return out, 0
    if n_holes > 0.5 * holes.size:
        raise FieldMapError("more than half of the samples inside the rim image are missing")
    n_t, n_p = block.shape
    cell = np.arange(n_t * n_p).reshape(n_t, n_p)
    up = np.roll(cell[:1], n_p // 2, axis=1) if pole and n_p % 2 == 0 else None
    centre = cell[: n_t - 1] if up is not None else cell[1: n_t - 1]
    t0 = 0 if up is not None else 1
    rows_t = np.arange(t0, n_t - 1)
    north = np.concatenate([up, cell[: n_t - 2]]) if up is not None else cell[: n_t - 2]
    stencil = [centre, north, cell[rows_t + 1], np.roll(centre, 1, axis=1),
               np.roll(centre, -1, axis=1)]
    last = cell[n_t - 1:]                      # the last row: one-sided theta difference
    stencil = [np.concatenate([a, b]) for a, b in zip(
        stencil, [last, cell[n_t - 3: n_t - 2], cell[n_t - 2: n_t - 1],
                  np.roll(last, 1, axis=1), np.roll(last, -1, axis=1)], strict=True)]
    weights = [np.concatenate([np.full(centre.size, w), np.full(last.size, v)])
               for w, v in zip((-4.0, 1.0, 1.0, 1.0, 1.0), (-1.0, 1.0, -2.0, 1.0, 1.0),
                               strict=True)]
    eq = np.arange(stencil[0].size)
    lap = sp.csr_matrix((np.concatenate(weights),
                         (np.tile(eq, 5), np.concatenate([c.ravel() for c in stencil]))),
                        shape=(eq.size, n_t * n_p))
    flat_holes = holes.ravel()
    touching = np.asarray(lap[:, flat_holes].getnnz(axis=1) > 0)
    lap = lap[touching]
    unknown = lap[:, flat_holes].tocsc()
    known = lap[:, ~flat_holes] @ block.ravel()[~flat_holes]
    normal = (unknown.T @ unknown).tocsc()
    block[holes] = spla.spsolve(normal, -(unknown.T @ known))
    return out, n_holes


def fill_along_phi(values: NDArray[np.float64], holes: NDArray[np.bool_],
                   n_rows: int) -> tuple[NDArray[np.float64], int]:
    """Fill the NaN samples among ``holes`` of the first ``n_rows`` rows along phi, row by row,
    by the periodic cubic spline through the row's finite samples.

    For holes narrow in phi and long in theta (the shadows of an obstacle's legs): across them
    a smooth field varies little, while along theta it may vary fast (the inpainting of
    :func:`fill_missing` then errs by the field's fourth theta derivative times the hole's
    width to the fourth). Rows with fewer than four finite samples are left as they are.
    Returns the filled copy and the number of samples filled.
    """
    from scipy.interpolate import CubicSpline

    out = np.array(values, dtype=np.float64, copy=True)
    n_p = out.shape[1]
    cells = np.arange(n_p, dtype=np.float64)
    count = 0
    for i in range(min(n_rows, out.shape[0])):
        row = out[i]
        fill = holes[i] & ~np.isfinite(row)
        known = np.isfinite(row)
        if not fill.any() or known.sum() < 4:
            continue
        x = np.append(cells[known], cells[known][0] + n_p)
        y = np.append(row[known], row[known][0])
        row[fill] = CubicSpline(x, y, bc_type="periodic")(
            np.where(cells[fill] < x[0], cells[fill] + n_p, cells[fill]))
        count += int(fill.sum())
    return out, count


def extend_rows(values: NDArray[np.float64], n_rows: int) -> NDArray[np.float64]:
    """Rows 0..n_rows-1 kept; EXTRA_ROWS more continued by the cubic through the last four."""
    k = np.arange(-3.0, 1.0)                                  # the last four rows, at 0
    coef = np.linalg.solve(np.vander(k, 4), values[n_rows - 4:n_rows])
    extra = np.vander(np.arange(1.0, EXTRA_ROWS + 1), 4) @ coef
    return np.concatenate([values[:n_rows], extra], axis=0)


def sphere_to_aperture(values: NDArray[np.float64], sphere: SphereGrid, aperture: ApertureGrid,
                       F: float, D: float) -> tuple[NDArray[np.float64], Coverage]:
    """Resample sphere samples (n_theta, n_phi) onto the aperture grid (N, N), NaN outside.

    ``values`` is any smooth quantity on the sphere (here FA); F and D in m. A scan that
    starts at theta_min > 0 leaves the polar cap without data: it is filled like any hole
    (:func:`fill_missing`, on rows aligned to the pole by :func:`from_the_pole`), and
    ``Coverage.n_filled`` counts the cap's whole rows of the scan's step (``n_rows`` stays
    the scan's own rows).
    """
    check_full_circle(sphere)
    n_scan_rows = usable_rows(sphere, F, D)
    theta_last = float(sphere.theta[n_scan_rows - 1])
    n_filled = (int(np.count_nonzero(~np.isfinite(values[:n_scan_rows])))
                + cap_rows(sphere) * sphere.n_phi)
    n_rows = n_scan_rows
    if sphere.theta_min > 1e-12:
        values, sphere, n_rows = from_the_pole(values, sphere, n_rows)
    filled, _ = fill_missing(values, n_rows)
    table = extend_rows(filled, n_rows)
    padded = _pad(table, sphere)
    mask = aperture.mask
    theta = 2.0 * np.arctan(aperture.r[mask] / (2.0 * F))
    phi = np.mod(aperture.phi[mask] - sphere.phi_min, 2.0 * np.pi) + sphere.phi_min
    it = (theta - sphere.theta[0]) / sphere.dtheta + PAD
    ip = (phi - sphere.phi[0]) / sphere.dphi + PAD
    out = np.full((aperture.N, aperture.N), np.nan)
    out[mask] = map_coordinates(padded, [it, ip], order=3, mode="nearest", prefilter=True)
    coverage = Coverage(n_scan_rows, theta_last, n_filled, theta_rim(D, F))
    return out, coverage


def from_the_pole(values: NDArray[np.float64], sphere: SphereGrid,
                  n_rows: int) -> tuple[NDArray[np.float64], SphereGrid, int]:
    """The first ``n_rows`` rows of a scan that starts at theta_min > 0, on rows of its own
    theta step that start half a step from the pole, with the polar cap's rows NaN (holes
    for :func:`fill_missing`, whose pole stencil and the spline's continuation across the
    pole both need row 0 half a step from it). Returns the values, their grid and row count.

    A start a whole number of steps from the pole keeps the scan's samples as they are. Any
    other start is moved onto the aligned rows by a cubic spline in theta, after its own
    holes are filled without the pole (one more cap row then covers the part step).
    """
    step, n_phi = sphere.dtheta, sphere.n_phi
    offset = sphere.theta_min / step          # the scan's first edge, in steps from the pole
    cap = cap_rows(sphere)
    if abs(offset - cap) < 1e-6:
        rows = values[:n_rows]
    else:
        from scipy.interpolate import CubicSpline

        own, _ = fill_missing(values, n_rows, pole=False)
        # aligned row j sits at (j + 1/2) steps, the scan's row i at offset + i + 1/2
        j = np.arange(cap + 1, int(np.floor(offset + n_rows - 1 + 1e-9)) + 1)
        rows = CubicSpline(np.arange(n_rows), own[:n_rows], axis=0)(j - offset)
        cap += 1
    out = np.concatenate([np.full((cap, n_phi), np.nan), rows], axis=0)
    aligned = SphereGrid(sphere.radius, out.shape[0], n_phi, 0.0, out.shape[0] * step,
                         sphere.phi_min, sphere.phi_max)
    return out, aligned, out.shape[0]


def cap_rows(sphere: SphereGrid) -> int:
    """Whole rows of the sphere's theta step that fit between the pole and the scan's first
    row (0 when it starts at the pole, or less than a step from it)."""
    return int(np.floor(sphere.theta_min / sphere.dtheta + 1e-6))


def _pad(table: NDArray[np.float64], sphere: SphereGrid) -> NDArray[np.float64]:
    """Pad PAD cells: periodic in phi; across the pole by phi + pi when theta starts at 0."""
    wrapped = np.concatenate([table[:, -PAD:], table, table[:, :PAD]], axis=1)
    n_p = sphere.n_phi
    if sphere.theta_min <= 1e-12 and n_p % 2 == 0:
        shifted = np.roll(table[:PAD], n_p // 2, axis=1)[::-1]
        before = np.concatenate([shifted[:, -PAD:], shifted, shifted[:, :PAD]], axis=1)
    else:
        before = np.repeat(wrapped[:1], PAD, axis=0)
    after = np.repeat(wrapped[-1:], PAD, axis=0)
    return np.concatenate([before, wrapped, after], axis=0)
