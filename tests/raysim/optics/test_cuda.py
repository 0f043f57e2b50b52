"""Every Warp kernel on CUDA against the CPU (float64): skipped where no GPU is present.

``scripts/device-check`` runs these wherever a GPU machine is lent. Agreement is measured
against the largest value of each quantity: GO intensity, PO currents and the PO, PTD and
magnetic radiation to 1e-10 of it (the two devices differ only in rounding: fused
multiply-adds, libm, the order of GO's atomic deposits), the shadow test exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid
from raysim.optics import go, po, ptd
from raysim.optics import runtime as warp_runtime
from raysim.optics.bvh import ReflectorBVH
from raysim.optics.radiator import CurrentElements, Radiator
from raysim.simulate import simulate
from raysim.surface.deformation import GaussianBumps
from raysim.surface.mesh import paraboloid
from raysim.surface.quadrature import plan

pytestmark = [pytest.mark.gpu,
              pytest.mark.skipif(not warp_runtime.init().is_cuda_available(), reason="no CUDA GPU here")]

RTOL = 1e-10
DEVICES = ("cpu", "cuda")  # the reference, the device checked
D, F, R = 12.0, 4.5, 2.0
BUMP = GaussianBumps(((1.0, -2.0, 3e-3, 1.5),))


PANELLED = """
name = "panelled"
[dish]
diameter_m = 20.0
focal_length_m = 7.5
resolution_m = 0.5
[panels]
ring_edges_m = [0.0, 5.0, 10.0]
panels_per_ring = [6, 12]
gap_m = 0.05
[[deformation]]
type = "panel_rigid"
rms_um = 200.0
seed = 3
[source]
frequency_hz = 1.0e9
incidence_theta_deg = 1.0
[sphere]
radius_m = 3.0
n_theta = 18
n_phi = 36
"""


def assert_agree(cuda, cpu, what: str) -> None:
    cuda, cpu = np.asarray(cuda), np.asarray(cpu)
    scale = np.abs(cpu).max()
    assert scale > 0, what
    err = np.abs(cuda - cpu).max() / scale
    assert err < RTOL, f"{what}: CUDA differs from the CPU by {err:.2e} of the largest value"


def test_go_intensity():
    """GO ray tubes on a panelled dish with gaps (shadows, folds), on and off axis."""
    from raysim.scene.scene import parse_scene
    from raysim.surface.mesh import reflectors_for

    scene = parse_scene(PANELLED)
    _, deformed = reflectors_for(scene)
    grid = scene.sphere
    for direction in ((0.0, 0.0, -1.0), (np.sin(0.05), 0.0, -np.cos(0.05))):
        cpu, cuda = (go.trace(deformed, grid, direction, 2, dev) for dev in DEVICES)
        assert_agree(cuda.intensity, cpu.intensity, f"GO intensity along {direction}")
        assert (cuda.n_shadowed, cuda.n_missed) == (cpu.n_shadowed, cpu.n_missed)


def test_shadow_test_and_po_currents():
    """The BVH shadow test of PO samples, exactly, and the PO current elements."""
    dish = paraboloid(D, F, 1.0).deformed(BUMP)
    wave = po.Illumination.plane_wave(2e9, (np.sin(1.2), 0.0, -np.cos(1.2)), (0.0, 1.0, 0.0))  # grazing: part in shadow
    quadrature = plan(dish, wave.wavelength, 1.5)
    samples = quadrature.samples()
    lit_cpu, lit_cuda = (ReflectorBVH.build(dish, dev).lit(samples.facet, wave.k_hat, samples.face)
                         for dev in DEVICES)
    assert np.array_equal(lit_cpu, lit_cuda) and 0 < lit_cpu.sum() < len(lit_cpu)
    cpu, cuda = (np.hstack([s.numpy() for s in po.po_elements(dish, wave, quadrature, dev, chunk=4096)])
                 for dev in DEVICES)
    assert cpu.shape == cuda.shape
    assert np.array_equal(cpu[:3], cuda[:3])  # positions: computed on the host
    assert_agree(cuda[3:], cpu[3:], "PO current elements")


@pytest.mark.parametrize("magnetic", [False, True])
def test_radiation_of_current_elements(magnetic):
    """The electric and magnetic radiation kernels (CPU: four points per thread; CUDA: one)."""
    rng = np.random.default_rng(7)
    n = 3000
    elements = CurrentElements(rng.uniform(-3, 3, (n, 3)),
                               rng.normal(size=(n, 3)) + 1j * rng.normal(size=(n, 3)), magnetic)
    points = rng.uniform(-8, 8, (1001, 3)) + np.array([0.0, 0.0, 12.0])
    fields = []
    for dev in DEVICES:
        radiator = Radiator(points, 2 * np.pi / 0.3, dev)
        radiator.add(elements)
        fields.append(radiator.field())
    assert_agree(fields[1], fields[0], f"{'magnetic' if magnetic else 'electric'} radiation")


def test_po_and_ptd_fields_of_a_dish():
    """PO and the rim's PTD fringe field at sphere points (the fringe kernel included)."""
    dish = paraboloid(D, F, 1.0).deformed(BUMP)
    wave = po.Illumination.plane_wave(1.5e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    grid = SphereGrid(R, 18, 36)
    cpu, cuda = (po.sphere_field(dish, grid, wave, 1.5, dev).E for dev in DEVICES)
    assert_agree(cuda, cpu, "PO field")
    cpu, cuda = (ptd.sphere_edge_field(dish, grid, wave, "rim", device=dev).E for dev in DEVICES)
    assert_agree(cuda, cpu, "PTD fringe field")


def test_simulate_on_cuda():
    """The FieldMaps of every method on CUDA against the CPU's (panels, gaps: all edges)."""
    from raysim.scene.scene import parse_scene

    scene = parse_scene(PANELLED)
    for method, kwargs in (("go", {}), ("po", {}), ("po+ptd", {"edges": "all"})):
        cpu, cuda = (simulate(scene, method, dev, **kwargs) for dev in DEVICES)
        for name in ("intensity", "intensity_ideal"):
            assert_agree(cuda[name].values, cpu[name].values, f"{method} {name}")
        assert cuda.attrs["device"] == DEVICES[1]


def test_fast_radiator_and_its_transpose_on_cuda():
    """The multilevel sum (leaf kernel, aggregation's re-phasing, the last step) and its
    transpose (the VJP's leaf and re-phasing kernels) on CUDA against the CPU's, forced on a
    dish large enough for a tree (the scaled dish of test_fast_radiator.py, 33 wavelengths
    across): both devices run the same plan, so they differ only in rounding."""
    from raysim.optics import po_jacobian
    from raysim.optics.fast.radiator import FastRadiator

    dish_d, dish_f = 10.0, 3.3
    wave = po.Illumination.plane_wave(1e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    dish = paraboloid(dish_d, dish_f, 1.0)
    points = SphereGrid(1.0, 24, 48).points(dish_f).reshape(-1, 3)
    src = np.hstack([s.numpy() for s in po.po_elements(dish, wave, plan(dish, wave.wavelength, 1.5))])
    sums, methods = [], []
    for dev in DEVICES:
        fast = FastRadiator(points, wave.k, dev, tol=1e-6, centre=(0.0, 0.0, dish_f), force=True)
        fast.add_packed(src, "electric")
        sums.append(fast.sums_of("electric"))
        methods.append(fast.method["electric"])
    assert methods[0].startswith("fast") and methods[1] == methods[0]
    assert_agree(sums[1], sums[0], "fast radiator")
    elements = po_jacobian.surface_elements(dish, wave, 1.5, "cpu")
    rng = np.random.default_rng(5)
    c = rng.normal(size=(len(points), 3)) + 1j * rng.normal(size=(len(points), 3))
    cpu, cuda = (po_jacobian.vjp(elements, points, c, dev, radiator="fast", tol=1e-6,
                                 centre=(0.0, 0.0, dish_f), force=True) for dev in DEVICES)
    assert_agree(np.stack(cuda), np.stack(cpu), "fast VJP (dz, dhx, dhy)")
