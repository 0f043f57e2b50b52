"""Warp kernels of the geometric-optics engine (see :mod:`raysim.optics.go`).

Two steps after the shadow test (:mod:`raysim.optics.kernels.visibility`), each a 1-D launch
that takes a trailing ``offset`` so it can be split across CPU threads: ``reflect_to_sphere``
(float64 reflection at the recomputed hit and intersection with the probe sphere, mapped to
the Lambert equal-area chart of the sphere) and ``deposit_tubes`` (each ray tube's power
spread over the (theta, phi) cells in proportion to the exact area of its overlap with each
cell in that chart). Before the deposit, ``chart_polar`` takes each ray's chart radius, theta
and phi once (a ray is a corner of about six tubes), and ``wedge_sides`` makes a grid's table
of the phi wedges' side normals once per tracer; the deposit reads them where it computed them
itself, the same numbers, so the cells receive the same power bit for bit.

The Lambert azimuthal equal-area chart about the sphere's pole -z maps the unit direction u
to X = sqrt(2 / (1 - u_z)) (u_x, u_y): |X| = 2 sin(theta / 2) and areas are sphere areas
(R = 1). A cell theta_a..theta_b, phi_a..phi_b is the annular sector between radii
2 sin(theta_a / 2) and 2 sin(theta_b / 2) and between the rays at phi_a and phi_b.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_TWO, F64_ZERO

wp.set_module_options({"enable_backward": False})

vec8d = wp.types.vector(length=8, dtype=wp.float64)
vec8i = wp.types.vector(length=8, dtype=wp.int32)



@wp.func
def sphere_entry(hit: wp.vec3d, n: wp.vec3d, k_hat: wp.vec3d, focus: wp.vec3d, radius: wp.float64):
    """The ray k_hat reflected at ``hit`` (unit normal n), r = k - 2 (k . n) n, and the distance
    s along it to where it enters the sphere |P - focus| = radius (the nearer root); s <= 0
    when it misses."""
    r = k_hat - F64_TWO * wp.dot(k_hat, n) * n
    w = hit - focus
    b = wp.dot(r, w)
    c = wp.dot(w, w) - radius * radius
    disc = b * b - c
    s = -F64_ONE
    if disc >= F64_ZERO:
        s = -b - wp.sqrt(disc)
    return r, s


@wp.func
def lambert(u: wp.vec3d) -> wp.vec2d:
    """The Lambert equal-area chart about -z of the unit vector u (module docstring)."""
    scale = wp.sqrt(F64_TWO / wp.max(F64_ONE - u[2], wp.float64(1e-300)))
    return wp.vec2d(scale * u[0], scale * u[1])


@wp.kernel
def reflect_to_sphere(
    hits: wp.array(dtype=wp.vec3d),
    normals: wp.array(dtype=wp.vec3d),
    k_hat: wp.vec3d,
    focus: wp.vec3d,
    radius: wp.float64,
    ok: wp.array(dtype=wp.int32),
    chart: wp.array(dtype=wp.vec2d),
    offset: int,
):
    """Reflect k_hat at each hit (float64) and meet the sphere |P - focus| = radius.

    chart[i] is the Lambert coordinate of the point where the reflected ray enters the
    sphere (:func:`sphere_entry`); ok[i] is cleared when the ray misses the sphere.
    """
    i = wp.tid() + offset
    if ok[i] == 0:
        return
    r, s = sphere_entry(hits[i], normals[i], k_hat, focus, radius)
    if s <= F64_ZERO:
        ok[i] = 0
        return
    chart[i] = lambert((hits[i] - focus + s * r) / radius)


@wp.func
def cross2(a: wp.vec2d, b: wp.vec2d) -> wp.float64:
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def signed_angle(a: wp.vec2d, b: wp.vec2d) -> wp.float64:
    """Angle from a to b about the origin (rad, -pi..pi); 0 when either is the origin."""
    return wp.atan2(cross2(a, b), wp.dot(a, b))


@wp.func
def edge_disk_part(a: wp.vec2d, b: wp.vec2d, rho: wp.float64) -> wp.vec2d:
    """Signed area of (triangle origin, a, b) inside the disk |X| <= rho, as (area, 0), or
    (0, 1) where it is the circular sector of the edge's whole angle, 0.5 rho^2
    ``signed_angle(a, b)``: that angle does not depend on rho, so the caller takes it once per
    edge for all the ring radii it meets.

    Inside the disk the triangle counts; outside it the circular sector of the same angle.
    Summed over a polygon's edges this is the area of polygon and disk in common.
    """
    d = b - a
    A = wp.dot(d, d)
    if A <= F64_ZERO:
        return wp.vec2d(F64_ZERO, F64_ZERO)
    B = wp.dot(a, d)
    C = wp.dot(a, a) - rho * rho
    disc = B * B - A * C
    r2 = F64_HALF * rho * rho
    if disc <= F64_ZERO:
        return wp.vec2d(F64_ZERO, F64_ONE)
    s = wp.sqrt(disc)
    t1 = (-B - s) / A
    t2 = (-B + s) / A
    if t2 <= F64_ZERO or t1 >= F64_ONE:
        return wp.vec2d(F64_ZERO, F64_ONE)
    # a..p1 and p2..b lie outside the disk (sectors), p1..p2 inside (triangle); an end inside
    # the disk has no sector, and its angle is never taken: near the origin it is meaningless
    area = F64_ZERO
    p1 = a
    if t1 > F64_ZERO:
        p1 = a + t1 * d
        area += r2 * signed_angle(a, p1)
    p2 = b
    if t2 < F64_ONE:
        p2 = a + t2 * d
        area += r2 * signed_angle(p2, b)
    return wp.vec2d(area + F64_HALF * cross2(p1, p2), F64_ZERO)


@wp.func
def polygon_area(px: vec8d, py: vec8d, n: int) -> wp.float64:
    total = F64_ZERO
    for k in range(n):
        k1 = (k + 1) % n
        total += px[k] * py[k1] - px[k1] * py[k]
    return F64_HALF * total


@wp.func
def segment_distance(a: wp.vec2d, b: wp.vec2d) -> wp.float64:
    """Distance from the origin to the segment a-b."""
    d = b - a
    L = wp.dot(d, d)
    t = F64_ZERO
    if L > F64_ZERO:
        t = wp.clamp(-wp.dot(a, d) / L, F64_ZERO, F64_ONE)
    return wp.length(a + t * d)


@wp.func
def wrap_angle(x: wp.float64) -> wp.float64:
    """x wrapped into (-pi, pi]."""
    two_pi = wp.float64(6.283185307179586)
    return x - two_pi * wp.floor((x + wp.float64(3.141592653589793)) / two_pi)


@wp.func
def wedge_normals(phi_min: wp.float64, dphi: wp.float64, j: int) -> wp.vec4d:
    """Inward normals (x, y of the side at alpha, x, y of the side at beta) of the wedge
    alpha = phi_min + j dphi .. beta = alpha + dphi."""
    alpha = phi_min + wp.float64(j) * dphi
    beta = alpha + dphi
    return wp.vec4d(-wp.sin(alpha), wp.cos(alpha), wp.sin(beta), -wp.cos(beta))


@wp.kernel
def wedge_sides(phi_min: wp.float64, dphi: wp.float64, j_first: int,
                sides: wp.array(dtype=wp.vec4d), offset: int):
    """sides[k]: :func:`wedge_normals` of wedge j = j_first + k (a grid's table, made once)."""
    k = wp.tid() + offset
    sides[k] = wedge_normals(phi_min, dphi, j_first + k)


@wp.kernel
def chart_polar(chart: wp.array(dtype=wp.vec2d), ok: wp.array(dtype=wp.int32),
                polar: wp.array(dtype=wp.vec3d), offset: int):
    """polar[i] = (|X|, theta = 2 asin(min(|X| / 2, 1)), phi = atan2(X_y, X_x)) of each ray
    that reached the sphere (chart X, Lambert radius; rad), for :func:`deposit_tubes`."""
    i = wp.tid() + offset
    if ok[i] == 0:
        return
    x = chart[i]
    r = wp.length(x)
    polar[i] = wp.vec3d(r, F64_TWO * wp.asin(wp.min(r * F64_HALF, F64_ONE)), wp.atan2(x[1], x[0]))


@wp.kernel
def deposit_tubes(
    chart: wp.array(dtype=wp.vec2d),
    ok: wp.array(dtype=wp.int32),
    tubes: wp.array(dtype=wp.vec3i),
    tube_power: wp.array(dtype=wp.float64),
    polar: wp.array(dtype=wp.vec3d),
    rho_edges: wp.array(dtype=wp.float64),
    sides: wp.array(dtype=wp.vec4d),
    j_first: int,
    theta_min: wp.float64,
    dtheta: wp.float64,
    n_theta: int,
    phi_min: wp.float64,
    dphi: wp.float64,
    n_phi: int,
    full_circle: int,
    power: wp.array2d(dtype=wp.float64),
    offset: int,
):
    """Spread each ray tube's power over the sphere cells it covers, by exact overlap area.

    A tube is the triangle of three rays' chart points; folds (reversed triangles) count with
    their absolute area. Cells outside the grid receive nothing; tubes with a ray that was
    shadowed or missed the sphere carry no power here.

    ``polar`` holds each ray's (|X|, theta, phi) from :func:`chart_polar` and ``sides`` the
    wedges' edge normals from :func:`wedge_sides` (wedge j at ``sides[j - j_first]``; a wedge
    outside the table computes its own): each ray is a corner of about six tubes and each
    wedge is cut by thousands, so their sines, arctangents and square roots are taken once.
    They are the very values this kernel would compute in their place, so the deposit is the
    same bit for bit.
    """
    t = wp.tid() + offset
    tri = tubes[t]
    if ok[tri[0]] == 0 or ok[tri[1]] == 0 or ok[tri[2]] == 0:
        return
    a = chart[tri[0]]
    b = chart[tri[1]]
    c = chart[tri[2]]
    qa = polar[tri[0]]
    qb = polar[tri[1]]
    qc = polar[tri[2]]
    area2 = cross2(b - a, c - a)
    if area2 < F64_ZERO:
        tmp = b
        b = c
        c = tmp
        qtmp = qb
        qb = qc
        qc = qtmp
        area2 = -area2
    P = tube_power[t]
    area = F64_HALF * area2
    two_pi = wp.float64(6.283185307179586)

    # a caustic: the tube has no extent on the sphere, its power lands in one cell
    if area <= wp.float64(1e-24):
        g = (a + b + c) / wp.float64(3.0)
        th = F64_TWO * wp.asin(wp.min(wp.length(g) * F64_HALF, F64_ONE))
        ph = wp.atan2(g[1], g[0])
        i0 = int(wp.floor((th - theta_min) / dtheta))
        j0 = int(wp.floor(wp.mod(ph - phi_min, two_pi) / dphi))
        if i0 >= 0 and i0 < n_theta and j0 >= 0 and j0 < n_phi:
            wp.atomic_add(power, i0, j0, P)
        return

    # radial (theta) extent of the triangle
    ra = qa[0]
    rb = qb[0]
    rc = qc[0]
    r_hi = wp.max(ra, wp.max(rb, rc))
    inside = cross2(a, b) >= F64_ZERO and cross2(b, c) >= F64_ZERO and cross2(c, a) >= F64_ZERO
    r_lo = F64_ZERO
    if not inside:
        r_lo = wp.min(segment_distance(a, b), wp.min(segment_distance(b, c), segment_distance(c, a)))
        # the pole on an edge (or a corner) to rounding: the corners' azimuths then span half a
        # turn, and which half is a rounding's choice. Taken as covering the pole, the tube is
        # clipped against every wedge, which holds exactly whichever side it lies on (a panel
        # edge imaged onto the pole lost a tube's power: 0.0223 m^2 of 9503 on a 110 m dish)
        if r_lo <= wp.float64(1e-9) * r_hi:
            inside = True
    th_lo = F64_TWO * wp.asin(wp.min(r_lo * F64_HALF, F64_ONE))
    # theta of the farthest corner: 2 asin(min(r_hi / 2, 1)) as chart_polar took it
    th_hi = qa[1]
    if r_hi == rb:
        th_hi = qb[1]
    if r_hi == rc:
        th_hi = qc[1]
    i_lo = int(wp.floor((th_lo - theta_min) / dtheta))
    i_hi = int(wp.floor((th_hi - theta_min) / dtheta))
    if i_hi < 0 or i_lo >= n_theta:
        return
    i_lo = wp.max(i_lo, 0)
    i_hi = wp.min(i_hi, n_theta - 1)

    # azimuthal extent: all wedges when the triangle covers the pole
    j_lo = int(0)
    j_hi = n_phi - 1
    # a partial grid: the wedges the extent meets a turn later (its part past phi_min + 2 pi)
    w_lo = int(0)
    w_hi = int(-1)
    if not inside:
        pa = qa[2]
        pb = pa + wrap_angle(qb[2] - pa)
        pc = pa + wrap_angle(qc[2] - pa)
        p_lo = wp.min(pa, wp.min(pb, pc))
        p_hi = wp.max(pa, wp.max(pb, pc))
        # the extent taken into [phi_min, phi_min + 2 pi) first: atan2's (-pi, pi] put a tube
        # a whole turn away from a grid on 90..270 deg, or one that crosses 180 deg
        turns = wp.floor((p_lo - phi_min) / two_pi)
        p_lo = p_lo - turns * two_pi
        p_hi = p_hi - turns * two_pi
        j_lo = int(wp.floor((p_lo - phi_min) / dphi))
        j_hi = int(wp.floor((p_hi - phi_min) / dphi))
        if full_circle == 1:
            if j_hi - j_lo + 1 >= n_phi:  # every wedge, each once (n_phi = 1: the one wedge)
                j_lo = 0
                j_hi = n_phi - 1
        elif p_hi >= phi_min + two_pi:
            w_lo = 0
            w_hi = wp.min(int(wp.floor((p_hi - two_pi - phi_min) / dphi)), n_phi - 1)
        # the radial and angular ranges are exact bounds: inside one cell, no clipping needed
        th_in = th_lo >= theta_min and th_hi <= theta_min + wp.float64(n_theta) * dtheta
        if i_lo == i_hi and j_lo == j_hi and th_in and w_hi < w_lo:
            jj = j_lo
            if full_circle == 1:
                jj = ((j_lo % n_phi) + n_phi) % n_phi
            if jj >= 0 and jj < n_phi:
                wp.atomic_add(power, i_lo, jj, P)
            return
        if full_circle == 0:  # the grid's wedges only
            j_lo = wp.max(j_lo, 0)
            j_hi = wp.min(j_hi, n_phi - 1)
            if w_hi >= j_lo:  # the two passes meet: one pass over the grid (a wedge once)
                j_lo = 0
                j_hi = n_phi - 1
                w_hi = -1

    n_first = wp.max(j_hi - j_lo + 1, 0)
    for k_pass in range(n_first + wp.max(w_hi - w_lo + 1, 0)):
        j = j_lo + k_pass
        if k_pass >= n_first:
            j = w_lo + k_pass - n_first
        jj = j
        if full_circle == 1:
            jj = ((j % n_phi) + n_phi) % n_phi
        elif j < 0 or j >= n_phi:
            continue
        # clip the triangle to the wedge phi_min + j dphi .. + dphi (two half-planes)
        px = vec8d()
        py = vec8d()
        px[0] = a[0]
        py[0] = a[1]
        px[1] = b[0]
        py[1] = b[1]
        px[2] = c[0]
        py[2] = c[1]
        n = int(3)
        if n_phi > 1 or full_circle == 0:  # one wedge of a whole turn needs no clipping
            k_side = j - j_first
            edge = wp.vec4d()
            if k_side >= 0 and k_side < sides.shape[0]:
                edge = sides[k_side]
            else:
                edge = wedge_normals(phi_min, dphi, j)
            for side in range(2):
                nx = edge[0]
                ny = edge[1]
                if side == 1:
                    nx = edge[2]
                    ny = edge[3]
                qx = vec8d()
                qy = vec8d()
                m = int(0)
                for k in range(n):
                    k1 = (k + 1) % n
                    s0 = nx * px[k] + ny * py[k]
                    s1 = nx * px[k1] + ny * py[k1]
                    if s0 >= F64_ZERO:
                        qx[m] = px[k]
                        qy[m] = py[k]
                        m += 1
                    if (s0 >= F64_ZERO) != (s1 >= F64_ZERO):
                        f = s0 / (s0 - s1)
                        qx[m] = px[k] + f * (px[k1] - px[k])
                        qy[m] = py[k] + f * (py[k1] - py[k])
                        m += 1
                px = qx
                py = qy
                n = m
        if n < 3:
            continue
        if polygon_area(px, py, n) <= F64_ZERO:
            continue
        # the clipped polygon's area inside the disks of the ring radii rho_edges[i_lo ..
        # i_hi + 1]; cell i gets the difference of radii i + 1 and i. Each edge's whole angle
        # is taken on its first need and kept for the other radii.
        angle = vec8d()
        have = vec8i()
        below = F64_ZERO
        for step in range(i_hi - i_lo + 2):
            rho = rho_edges[i_lo + step]
            r2 = F64_HALF * rho * rho
            upto = F64_ZERO
            for k in range(n):
                k1 = (k + 1) % n
                e0 = wp.vec2d(px[k], py[k])
                e1 = wp.vec2d(px[k1], py[k1])
                part = edge_disk_part(e0, e1, rho)
                term = part[0]
                if part[1] > F64_ZERO:
                    if have[k] == 0:
                        angle[k] = signed_angle(e0, e1)
                        have[k] = 1
                    term = r2 * angle[k]
                upto += term
            if step > 0:
                share = upto - below
                if share > F64_ZERO:
                    wp.atomic_add(power, i_lo + step - 1, jj, P * share / area)
            below = upto
