"""The rim's image under a deformed surface (solver.rimimage), and the inversion leaving out the
rows it crosses."""

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid, theta_rim
from solver.rimimage import rim_ray_theta, rows_clear_of_rim

D, F, R = 50.0, 20.0, 10.0


def test_the_ideal_rim_ray_lands_on_the_rim_image():
    phi = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    zero = np.zeros_like(phi)
    theta = rim_ray_theta(F, D, R, phi, zero, zero, zero)
    assert theta == pytest.approx(np.full(8, theta_rim(D, F)), abs=1e-12)


@pytest.mark.parametrize("c", [2e-5, -3e-5])
def test_a_paraboloid_of_another_focal_length_aims_its_rim_ray_at_its_own_focus(c):
    """delta = c r^2 makes the paraboloid of 1/4F' = 1/4F + c: the rim's ray heads for its focus
    (0, 0, F') (the focusing property), whose line meets the circle of radius R about the old
    focus where plane geometry puts it."""
    a = 0.5 * D
    F2 = 1.0 / (1.0 / F + 4.0 * c)
    rim = np.array([a, a * a / (4.0 * F2)])          # (x, z) of the rim point
    u = np.array([0.0, F2]) - rim
    u /= np.linalg.norm(u)
    p = rim - np.array([0.0, F])                     # from the old focus
    t = -p @ u - np.sqrt((p @ u) ** 2 - (p @ p - R * R))
    hit = p + t * u
    expected = np.arctan2(hit[0], -hit[1])
    phi = np.array([0.0, 1.0, 2.5])
    theta = rim_ray_theta(F, D, R, phi, np.full(3, c * a * a), 2.0 * c * a * np.cos(phi),
                          2.0 * c * a * np.sin(phi))
    assert theta == pytest.approx(np.full(3, expected), abs=1e-12)
    assert np.all((theta < theta_rim(D, F)) == (c > 0))  # a deeper dish: its rim ray inward


def test_rows_are_dropped_only_when_the_image_can_reach_them():
    sphere = SphereGrid(R, 45, 180)                 # 2 deg rows; the rim image at 64.011 deg
    n = 32                                          # the last one ends at 64 deg
    margin = theta_rim(D, F) - np.radians(64.0)
    assert rows_clear_of_rim(sphere, F, D, n, np.array([0.5 * margin, -0.9 * margin])) == n
    assert rows_clear_of_rim(sphere, F, D, n, np.array([0.0, -1.1 * margin])) == n - 1
    assert rows_clear_of_rim(sphere, F, D, n, np.array([1.1 * margin])) == n - 1  # either way
    # never so far that the data stop more than three cells short of the rim image
    assert rows_clear_of_rim(sphere, F, D, n, np.array([np.radians(10.0)])) == n - 2


@pytest.mark.slow
def test_a_row_the_rim_image_crosses_is_left_out():
    """Z(8, 4) of 60 um on a 50 m dish of F/D = 0.4, 2 deg rows (the last ends 0.011 deg inside
    the rim image, which the surface moves by 0.04 deg), 64 exact rim targets: the row took
    the map to 19 um of error; without it 0.35 um."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate
    from solver.boundary import RimTargets
    from solver.invert import invert

    scene = parse_scene('name = "z84"\n[dish]\ndiameter_m = 50.0\nfocal_length_m = 20.0\n'
                        'resolution_m = 0.15\n[[deformation]]\ntype = "zernike"\n'
                        'terms = [[8, 4, 60.0]]\nradius_m = 25.0\n'
                        '[source]\nfrequency_hz = 0.3e9\n'
                        '[sphere]\nradius_m = 10.0\nn_theta = 45\nn_phi = 180\n')
    phi = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    x, y = 25.0 * np.cos(phi), 25.0 * np.sin(phi)
    targets = RimTargets(x, y, np.asarray(scene.deformation(x, y), dtype=np.float64))
    from solver.forward import GOForward

    class Counting(GOForward):
        """The GO model, counting its runs (the inversion solves twice here)."""

        runs = 0

        def __call__(self, *args, **kwargs):
            Counting.runs += 1
            return super().__call__(*args, **kwargs)

    surface = invert(simulate(scene, method="go"), rim=targets, forward=Counting())
    assert surface.attrs["rows_dropped_at_rim"] == 1
    assert surface.attrs["refine_forward_runs"] == Counting.runs >= 2 * 5  # both solves
    assert surface.attrs["theta_last_used_deg"] == pytest.approx(61.0)
    assert surface.attrs["rms_m"] < 2e-6
