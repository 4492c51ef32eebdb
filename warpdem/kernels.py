"""Warp kernels of the engine: sphere placement, body integration, wall motion, neighbour lists;
the geometry and contact helpers the contact stages (:mod:`warpdem.stages`) share.

All kernels run unchanged on ``cpu`` and ``cuda``. Layout (see docs/engine.md, "Design in one screen"):
structure of arrays, body-major (the member spheres of a body are contiguous), one thread
per sphere for contacts (full neighbour list: each pair is evaluated from both sides, so no
atomics are needed for particle forces and results are deterministic), one thread per body
for integration.
"""
from __future__ import annotations

import functools

import warp as wp

from .layouts import DEFAULT_SLOT_LAYOUT, entry_function

# Engine kernels need no adjoints (halves compile time); fast math for sqrt/div/log on CUDA.
wp.set_module_options({"enable_backward": False, "fast_math": True})

# Wall contacts of one wall whose normals agree within this cosine are one contact
# (a sphere touching two triangles of a flat or gently curved face feels one force).
WALL_MERGE_COS = wp.constant(0.99)
# History of a wall contact is matched to last step's contact of the same wall if their
# normals agree within this cosine (the wall-force stage; also pump.wear's impact recorder).
WALL_MATCH_COS = wp.constant(0.7)
# Marks a wall slot dropped during collection (never a sphere index or wall tag).
SLOT_EMPTY = wp.constant(-2147483647)


# ----------------------------------------------------------------------------- geometry
@wp.func
def closest_point_triangle(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """Closest point to p on triangle abc (Ericson 2005, Real-Time Collision Detection, 5.1.5)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return a
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return b
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        return a + ab * (d1 / (d1 - d3))
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return c
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        return a + ac * (d2 / (d2 - d6))
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return a + ab * v + ac * w


@wp.func
def wall_motion_time(t: wp.float64, t_start: float, t_stop: float):
    """Elapsed motion time tau = clamp(t, t_start, t_stop) - t_start [s] (float64)."""
    ts = wp.float64(t_start)
    te = wp.float64(t_stop)
    return wp.min(wp.max(t, ts), te) - ts


@wp.func
def wall_is_moving(t: wp.float64, t_start: float, t_stop: float):
    return t >= wp.float64(t_start) and t < wp.float64(t_stop)


@wp.func
def wall_point_velocity(t: wp.float64, t_start: float, t_stop: float, origin: wp.vec3, lin_vel: wp.vec3,
                        ang_vel: wp.vec3, point: wp.vec3):
    """Velocity [m/s] of the wall material at ``point`` at time ``t``: v + w x (p - c(t)), with
    c(t) the rotation centre moved with the wall; zero outside the motion's time window."""
    if not wall_is_moving(t, t_start, t_stop):
        return wp.vec3(0.0)
    centre = origin + lin_vel * float(wall_motion_time(t, t_start, t_stop))
    return lin_vel + wp.cross(ang_vel, point - centre)


@wp.func
def wall_rotation(t: wp.float64, t_start: float, t_stop: float, ang_vel: wp.vec3):
    """Rotation R(w tau) of a wall turning at ``ang_vel`` [rad/s] for tau = elapsed motion time
    (the angle is reduced modulo 2 pi in float64 so that long runs keep float32 precision)."""
    w_len = wp.length(ang_vel)
    if w_len > 0.0:
        angle = wp.float64(w_len) * wall_motion_time(t, t_start, t_stop)
        angle = angle - wp.float64(2.0 * wp.pi) * wp.floor(angle / wp.float64(2.0 * wp.pi))
        return wp.quat_from_axis_angle(ang_vel / w_len, float(angle))
    return wp.quat_identity()


@wp.func
def wall_centre(t: wp.float64, t_start: float, t_stop: float, origin: wp.vec3, lin_vel: wp.vec3):
    """Where the wall's rotation centre is at time t: c(t) = c0 + v tau [m]."""
    return origin + lin_vel * float(wall_motion_time(t, t_start, t_stop))


@wp.func
def point_in_wall_rest_frame(x: wp.vec3, t: wp.float64, t_start: float, t_stop: float, origin: wp.vec3,
                             lin_vel: wp.vec3, ang_vel: wp.vec3):
    """Where the point ``x`` [m] lies in a rigidly moving wall's rest mesh at time ``t``:
    x0 = c0 + R^T (x - c(t)); also returns R and c(t) to map results back (x = c(t) + R (x0 - c0))."""
    rot = wall_rotation(t, t_start, t_stop, ang_vel)
    c_now = wall_centre(t, t_start, t_stop, origin, lin_vel)
    return origin + wp.quat_rotate_inv(rot, x - c_now), rot, c_now


# A wall moves rigidly: a point x0 of its rest mesh is at  x(t) = c(t) + R(w tau) (x0 - c0).
# The engine never moves the mesh: a sphere at x is looked up in the rest mesh at
# x0 = c0 + R^T (x - c(t)), and the closest point and normal found there are mapped back.
# So no wall needs its vertices placed and its BVH refitted each step.


# ----------------------------------------------------------------------------- bodies
@wp.struct
class SphereView:
    """What a contact needs of a sphere, packed in 64 bytes so that one neighbour costs one
    gather instead of ten (radius < 0 marks a sphere of an inactive body)."""

    x: wp.vec3  # sphere centre [m]
    r: float  # radius [m]
    v: wp.vec3  # body velocity [m/s]
    m: float  # body mass [kg]
    w: wp.vec3  # body angular velocity [rad/s]
    i_mean: float  # mean principal moment of inertia of the body [kg m^2]
    xb: wp.vec3  # body centre of mass [m]
    mat: int  # material index


@wp.func
def sphere_view(x: wp.vec3, radius: float, material: int, xb: wp.vec3, v: wp.vec3, w: wp.vec3, mass: float,
                inertia: wp.vec3, active: int):
    """The :class:`SphereView` of a sphere at ``x`` [m] of a body at ``xb`` [m] moving at ``v``,
    ``w`` (radius -1 if the body is inactive)."""
    sv = SphereView()
    sv.x = x
    sv.r = radius
    if active == 0:
        sv.r = -1.0
    sv.v = v
    sv.m = mass
    sv.w = w
    sv.i_mean = (inertia[0] + inertia[1] + inertia[2]) / 3.0
    sv.xb = xb
    sv.mat = material
    return sv


@wp.struct
class MemberPlacement:
    """What places spheres from their bodies: the model's bodies and spheres, the packed views, and
    the device flag that asks the next step to place every sphere itself. Read by the placement
    launches and, with ``DEMSolver(fused_placement=True)``, by the integrator right after it moved
    a body."""

    body: wp.array(dtype=int)  # body of each sphere (Model.sphere_body)
    first: wp.array(dtype=int)  # first member sphere of each body (Model.body_first)
    count: wp.array(dtype=int)  # member spheres of each body (Model.body_count)
    mass: wp.array(dtype=float)  # body mass [kg]
    inertia: wp.array(dtype=wp.vec3)  # principal moments of inertia [kg m^2]
    offset: wp.array(dtype=wp.vec3)  # sphere centre in the body frame [m]
    radius: wp.array(dtype=float)  # sphere radius [m]
    material: wp.array(dtype=int)  # sphere material index
    views: wp.array(dtype=SphereView)  # the solver's packed views (of the State just written)
    request: wp.array(dtype=int)  # [0] != 0: the views are stale, the next step places them all


@wp.struct
class BodyStates:
    """The bodies of one State: what the integrator reads (``in``) or writes (``out``) and the
    placement reads (:meth:`warpdem.model.State` arrays of the same names)."""

    active: wp.array(dtype=int)  # 1 active, 0 removed
    q: wp.array(dtype=wp.vec3)  # centre of mass [m]
    rot: wp.array(dtype=wp.quat)  # orientation (body to world)
    v: wp.array(dtype=wp.vec3)  # velocity [m/s]
    w: wp.array(dtype=wp.vec3)  # angular velocity [rad/s]


@wp.func
def place_sphere(i: int, members: MemberPlacement, bodies: BodyStates, sphere_x: wp.array(dtype=wp.vec3)):
    """Sphere i's position from its body's pose, and its packed :class:`SphereView`."""
    b = members.body[i]
    xb = bodies.q[b]
    x = xb + wp.quat_rotate(bodies.rot[b], members.offset[i])
    sphere_x[i] = x
    members.views[i] = sphere_view(x, members.radius[i], members.material[i], xb, bodies.v[b], bodies.w[b],
                                   members.mass[b], members.inertia[b], bodies.active[b])


@wp.kernel
def place_sphere_views(members: MemberPlacement, bodies: BodyStates, sphere_x: wp.array(dtype=wp.vec3)):
    """Sphere positions from body poses, and each sphere's packed :class:`SphereView`."""
    place_sphere(wp.tid(), members, bodies, sphere_x)


# threads of the grid-stride placement launch of ``fused_placement`` (an early exit on most steps)
MAX_PLACEMENT_THREADS = 1 << 16


@wp.kernel
def place_sphere_views_on_request(rebuild: wp.array(dtype=int), num_spheres: int, stride: int,
                                  members: MemberPlacement, bodies: BodyStates, sphere_x: wp.array(dtype=wp.vec3)):
    """:func:`place_sphere_views` (grid-stride, ``stride`` = the launch's thread count) only if
    ``members.request[0]`` (the views are not this State's: first step, a State changed between
    steps) or ``rebuild[0]`` (a list rebuild asked for before the step: bodies were added, moved or
    removed) is set; else every thread returns at once. With ``fused_placement`` the integrator
    places the spheres of the State it writes (:func:`integrate_bodies_kernel`) and clears the request."""
    if members.request[0] == 0 and rebuild[0] == 0:
        return
    for i in range(wp.tid(), num_spheres, stride):
        place_sphere(i, members, bodies, sphere_x)


@wp.func
def place_members(b: int, xb: wp.vec3, rot: wp.quat, v: wp.vec3, w: wp.vec3, active: int, members: MemberPlacement,
                  sphere_x: wp.array(dtype=wp.vec3)):
    """Positions and views of body b's member spheres for the pose ``xb``, ``rot`` and velocities
    ``v``, ``w`` just written (the same values :func:`place_sphere_views` would read back)."""
    first = members.first[b]
    mass = members.mass[b]
    inertia = members.inertia[b]
    for s in range(first, first + members.count[b]):
        x = xb + wp.quat_rotate(rot, members.offset[s])
        sphere_x[s] = x
        members.views[s] = sphere_view(x, members.radius[s], members.material[s], xb, v, w, mass, inertia, active)


@wp.func
def effective_youngs_modulus(e_i: float, nu_i: float, e_j: float, nu_j: float):
    """Hertz's effective Young's modulus E* = 1 / ((1 - nu_i^2) / E_i + (1 - nu_j^2) / E_j) [Pa]
    (warpdem.contact.hertz_mindlin)."""
    return 1.0 / ((1.0 - nu_i * nu_i) / e_i + (1.0 - nu_j * nu_j) / e_j)


@wp.func
def effective_shear_modulus(e_i: float, nu_i: float, e_j: float, nu_j: float):
    """Mindlin & Deresiewicz (1953) effective shear modulus G* = 1 / ((2 - nu_i) / G_i + (2 - nu_j) / G_j),
    G = E / (2 (1 + nu)) [Pa] (warpdem.contact.hertz_mindlin: the seed paper's eqs. (7)/(10) misprint it)."""
    g_i = e_i / (2.0 * (1.0 + nu_i))
    g_j = e_j / (2.0 * (1.0 + nu_j))
    return 1.0 / ((2.0 - nu_i) / g_i + (2.0 - nu_j) / g_j)


@wp.func
def mass_felt_at(m: float, i_mean: float, lever: wp.vec3, n: wp.vec3):
    """Effective mass [kg] of a rigid body along the unit normal ``n`` at a contact reached
    by ``lever`` [m] from its centre of mass: 1 / (1/m + |lever x n|^2 / I), the inverse of
    the point's normal compliance, with the inertia taken isotropic (``i_mean``, the mean
    principal moment [kg m^2]). A sphere (lever 0, or along n) feels exactly m. Used as m*
    in the contact damping, so that an off-centre contact on a clump (which also turns the
    body) gets the restitution it is given (Kruggel-Emden et al. 2008, Powder Technol.
    188:153; Brogliato 2016, Nonsmooth Mechanics, ch. 4)."""
    a = wp.cross(lever, n)
    k = wp.dot(a, a)
    if k > 0.0 and i_mean > 0.0:
        return 1.0 / (1.0 / m + k / i_mean)
    return m


@wp.func
def whole_body_mass(m: float, i_mean: float, lever: wp.vec3, n: wp.vec3):
    """The body's whole mass m [kg] as the contact's damping mass, whatever the lever (the
    convention of LIGGGHTS ``fix multisphere`` and many codes); same arguments as
    :func:`mass_felt_at`, which it replaces for ``ContactLaw(clump_damping_mass="body")``."""
    return m


@wp.func
def body_lever(offset: wp.vec3, arm: float, n: wp.vec3):
    """Distance [m] from a contact point to the centre of mass of the sphere's body: the point
    lies ``arm`` [m] from the sphere centre against the unit normal ``n``, and the sphere centre
    ``offset`` [m] from the body's centre of mass, so |offset - arm n|. A sphere of its own
    (offset 0) gets ``arm`` itself, bit for bit. The lever of EDEM's rolling friction
    (:class:`warpdem.contact.rolling.BodyArmCDT`)."""
    if wp.dot(offset, offset) == 0.0:
        return arm
    return wp.length(offset - arm * n)


def damping_mass_function(convention: str) -> "wp.Function":
    """The ``wp.func`` (m, i_mean, lever, n) -> m_i [kg] of a clump damping convention
    (:attr:`warpdem.contact.law.ContactLaw.clump_damping_mass`), chosen when a stage kernel is
    built, so the default costs nothing at run time."""
    functions = {"contact_point": mass_felt_at, "body": whole_body_mass}
    if convention not in functions:
        raise ValueError(f"unknown clump_damping_mass {convention!r}; valid: {list(functions)}")
    return functions[convention]


@wp.func
def angular_velocity_from_momentum(r: wp.quatd, l: wp.vec3d, inertia: wp.vec3d):
    """w = R I^-1 R^T L (world frame) for principal inertia ``inertia``."""
    return wp.quat_rotate(r, wp.cw_div(wp.quat_rotate_inv(r, l), inertia))


@wp.func
def rotate_by(r: wp.quatd, w: wp.vec3d, h: wp.float64):
    """exp(h w) R: the orientation R turned by the rotation vector h w."""
    wl = wp.length(w)
    if wl * h < wp.float64(1.0e-300):
        return r
    return wp.normalize(wp.quat_from_axis_angle(w / wl, wl * h) * r)


@functools.lru_cache(maxsize=None)
def integrate_bodies_kernel(place_members_after: bool = False) -> "wp.Kernel":
    """The body integrator (:func:`integrate_bodies` below), built once per choice.

    ``place_members_after`` (``DEMSolver(fused_placement=True)``): the thread of a body also
    writes its member spheres' positions (the output State's ``sphere_x_out``) and packed views
    from the pose and velocities it has just written (:func:`place_members`), and thread 0 clears
    ``members.request``: the views are then the output State's, so the next step needs no
    placement launch (which would read every body again). Without it, ``members`` and
    ``sphere_x_out`` are not touched."""
    fused = bool(place_members_after)

    @wp.kernel
    def integrate_bodies(
        members: MemberPlacement,
        body_world: wp.array(dtype=int),
        sphere_f: wp.array(dtype=wp.vec3),
        sphere_t: wp.array(dtype=wp.vec3),
        external_f: wp.array(dtype=wp.vec3),
        use_external: int,
        gravity: wp.vec3,
        dt: float,
        bodies_in: BodyStates,
        bodies_out: BodyStates,
        world_paused: wp.array(dtype=int),
        sphere_x_out: wp.array(dtype=wp.vec3),
    ):
        """Semi-implicit (symplectic) Euler step of rigid bodies. Removed bodies and bodies of a
        paused world keep their pose at rest (unstable results are caught afterwards by
        :func:`isolate_unstable_bodies`).

        Translation: v' = v + (F/m + g) dt, x' = x + v' dt.
        Rotation (asymmetric bodies): the world angular momentum L = R I R^T w is advanced by the
        torque, L' = L + T dt (exactly conserved without torque); the quaternion is advanced with
        the angular velocity w = R I^-1 R^T L' and renormalised; w' is recomputed from L' at the
        new orientation so that the body frame and L stay consistent (cf. Rapaport 2004, The Art
        of Molecular Dynamics Simulation, ch. 8; "NO_SQUISH"-style angular-momentum form).
        Member forces are summed in a fixed order (no atomics: deterministic).
        """
        b = wp.tid()
        if wp.static(fused):
            if b == 0:  # the placement launch of this step has run: the views will be those written here
                members.request[0] = 0
        act = bodies_in.active[b]
        bodies_out.active[b] = act
        if act == 0 or world_paused[body_world[b]] != 0:
            bodies_out.q[b] = bodies_in.q[b]
            bodies_out.rot[b] = bodies_in.rot[b]
            bodies_out.v[b] = wp.vec3(0.0)
            bodies_out.w[b] = wp.vec3(0.0)
            if wp.static(fused):
                place_members(b, bodies_in.q[b], bodies_in.rot[b], wp.vec3(0.0), wp.vec3(0.0), act, members, sphere_x_out)
            return
        f = wp.vec3(0.0)
        t = wp.vec3(0.0)
        first = members.first[b]
        for s in range(first, first + members.count[b]):
            f = f + sphere_f[s]
            t = t + sphere_t[s]
        if use_external != 0:
            f = f + external_f[b]
        m = members.mass[b]
        v = bodies_in.v[b] + (f / m + gravity) * dt
        x = bodies_in.q[b] + v * dt
        # rotation in float64: angular momentum L = R I R^T w advanced by the torque, orientation
        # by the implicit midpoint rule R' = exp(h w_half) R with w_half = w(L, exp(h/2 w_half) R)
        # (three fixed-point sweeps); conserves |L| exactly and E to O(h^2) without float32 drift
        rf = bodies_in.rot[b]
        r = wp.normalize(wp.quatd(wp.float64(rf[0]), wp.float64(rf[1]), wp.float64(rf[2]), wp.float64(rf[3])))
        inertia_f = members.inertia[b]
        inertia = wp.vec3d(wp.float64(inertia_f[0]), wp.float64(inertia_f[1]), wp.float64(inertia_f[2]))
        wf = bodies_in.w[b]
        w0 = wp.vec3d(wp.float64(wf[0]), wp.float64(wf[1]), wp.float64(wf[2]))
        h = wp.float64(dt)
        torque_h = wp.vec3d(wp.float64(t[0]), wp.float64(t[1]), wp.float64(t[2])) * h
        r_new64 = r
        w_new64 = w0
        if inertia_f[0] == inertia_f[1] and inertia_f[1] == inertia_f[2]:
            # isotropic body (every single sphere): L = I w whatever the orientation, so the
            # midpoint sweeps below return w_half = w' = w + T dt / I at once; the same update
            # without them (equal to their result up to float64 rounding)
            w_new64 = w0 + torque_h / inertia[0]
            r_new64 = rotate_by(r, w_new64, h)
        else:
            l_world = wp.quat_rotate(r, wp.cw_mul(inertia, wp.quat_rotate_inv(r, w0))) + torque_h
            w_half = angular_velocity_from_momentum(r, l_world, inertia)
            for _sweep in range(3):
                w_half = angular_velocity_from_momentum(rotate_by(r, w_half, wp.float64(0.5) * h), l_world, inertia)
            r_new64 = rotate_by(r, w_half, h)
            w_new64 = angular_velocity_from_momentum(r_new64, l_world, inertia)
        r_new = wp.quat(float(r_new64[0]), float(r_new64[1]), float(r_new64[2]), float(r_new64[3]))
        w_new = wp.vec3(float(w_new64[0]), float(w_new64[1]), float(w_new64[2]))
        bodies_out.q[b] = x
        bodies_out.rot[b] = r_new
        bodies_out.v[b] = v
        bodies_out.w[b] = w_new
        if wp.static(fused):
            place_members(b, x, r_new, v, w_new, act, members, sphere_x_out)

    return integrate_bodies


# Causes of an unstable world (``DEMSolver.world_fail``): the first one seen is kept.
UNSTABLE_NONFINITE = wp.constant(1)
UNSTABLE_SPEED = wp.constant(2)


@functools.lru_cache(maxsize=None)
def isolate_unstable_bodies_kernel(place_members_after: bool = False) -> "wp.Kernel":
    """The instability check (:func:`isolate_unstable_bodies` below), built once per choice;
    ``place_members_after`` as in :func:`integrate_bodies_kernel`: a body put back to its last
    pose has its member spheres placed again there."""
    fused = bool(place_members_after)

    @wp.kernel
    def isolate_unstable_bodies(
        body_world: wp.array(dtype=int),
        bodies_in: BodyStates,
        bodies_out: BodyStates,
        v_max: float,
        world_fail: wp.array(dtype=int),
        world_paused: wp.array(dtype=int),
        members: MemberPlacement,
        sphere_x_out: wp.array(dtype=wp.vec3),
    ):
        """After integration: a body whose new state is NaN/inf (cause 1) or faster than
        ``v_max`` [m/s] (cause 2) is put back to its last pose at rest, its world's first cause is
        recorded in ``world_fail`` and the world is paused, so the bad values never reach another
        step or another world. Reads no pause flag (the flags it writes act from the next step)."""
        b = wp.tid()
        if bodies_out.active[b] == 0:
            return
        v = bodies_out.v[b]
        w = bodies_out.w[b]
        r = bodies_out.rot[b]
        code = int(0)
        if not (wp.isfinite(bodies_out.q[b]) and wp.isfinite(v) and wp.isfinite(w)
                and wp.isfinite(r[0]) and wp.isfinite(r[1]) and wp.isfinite(r[2]) and wp.isfinite(r[3])):
            code = UNSTABLE_NONFINITE
        elif wp.dot(v, v) > v_max * v_max:
            code = UNSTABLE_SPEED
        if code == 0:
            return
        world = body_world[b]
        wp.atomic_cas(world_fail, world, 0, code)
        world_paused[world] = 1
        bodies_out.q[b] = bodies_in.q[b]
        bodies_out.rot[b] = bodies_in.rot[b]
        bodies_out.v[b] = wp.vec3(0.0)
        bodies_out.w[b] = wp.vec3(0.0)
        if wp.static(fused):
            place_members(b, bodies_in.q[b], bodies_in.rot[b], wp.vec3(0.0), wp.vec3(0.0), bodies_out.active[b], members,
                          sphere_x_out)

    return isolate_unstable_bodies


@wp.kernel
def release_worlds(world_fail: wp.array(dtype=int), world_paused: wp.array(dtype=int)):
    """Unpause every world except those frozen as unstable."""
    w = wp.tid()
    world_paused[w] = wp.where(world_fail[w] != 0, 1, 0)


@wp.kernel
def stop_paused_bodies(body_world: wp.array(dtype=int), world_paused: wp.array(dtype=int),
                       v: wp.array(dtype=wp.vec3), w: wp.array(dtype=wp.vec3)):
    """Zero the velocities of bodies in paused worlds (their contacts then carry no increments)."""
    b = wp.tid()
    if world_paused[body_world[b]] != 0:
        v[b] = wp.vec3(0.0)
        w[b] = wp.vec3(0.0)


@wp.kernel
def advance_time(time_in: wp.array(dtype=wp.float64), dt: float, time_out: wp.array(dtype=wp.float64)):
    time_out[0] = time_in[0] + wp.float64(dt)


@wp.kernel
def deactivate_outside(
    body_q: wp.array(dtype=wp.vec3),
    lower: wp.vec3,
    upper: wp.vec3,
    active: wp.array(dtype=int),
    body_world: wp.array(dtype=int),
    world_on: wp.array(dtype=int),
    removed: wp.array(dtype=int),
):
    """Remove (deactivate) bodies of the worlds with ``world_on`` != 0 whose centre leaves the box
    [lower, upper]; counts removals."""
    b = wp.tid()
    if active[b] == 0 or world_on[body_world[b]] == 0:
        return
    x = body_q[b]
    if x[0] < lower[0] or x[1] < lower[1] or x[2] < lower[2] or x[0] > upper[0] or x[1] > upper[1] or x[2] > upper[2]:
        active[b] = 0
        wp.atomic_add(removed, 0, 1)


@wp.kernel
def wall_overlap(
    sphere_x: wp.array(dtype=wp.vec3),
    sphere_radius: wp.array(dtype=float),
    sphere_world: wp.array(dtype=int),
    wall_mesh: wp.array(dtype=wp.uint64),
    world_wall_start: wp.array(dtype=int),
    world_wall_index: wp.array(dtype=int),
    wall_lin_vel: wp.array(dtype=wp.vec3),
    wall_ang_vel: wp.array(dtype=wp.vec3),
    wall_origin: wp.array(dtype=wp.vec3),
    wall_t_start: wp.array(dtype=float),
    wall_t_stop: wp.array(dtype=float),
    t: wp.float64,
    depth: wp.array(dtype=float),
    wall_of: wp.array(dtype=int),
):
    """Deepest overlap [m] of each sphere with a wall of its world at time ``t`` [s] (walls
    placed by their motion, looked up in their rest frame) and that wall's index (-1: none)."""
    i = wp.tid()
    xi = sphere_x[i]
    ri = sphere_radius[i]
    world = sphere_world[i]
    best = float(0.0)
    which = int(-1)
    for kk in range(world_wall_start[world], world_wall_start[world + 1]):
        k = world_wall_index[kk]
        x_rest, rot, c_now = point_in_wall_rest_frame(xi, t, wall_t_start[k], wall_t_stop[k], wall_origin[k],
                                                      wall_lin_vel[k], wall_ang_vel[k])
        q = wp.mesh_query_point_no_sign(wall_mesh[k], x_rest, ri)
        if q.result:
            cp = wp.mesh_eval_position(wall_mesh[k], q.face, q.u, q.v)
            ov = ri - wp.length(x_rest - cp)
            if ov > best:
                best = ov
                which = k
    depth[i] = best
    wall_of[i] = which


# ----------------------------------------------------------------------------- neighbours
# The list build reads and writes packed structs, like the contact stages (warpdem.stages):
# ``ListSpheres`` (packed per State, ``DEMSolver._list_spheres``), ``WallSet`` and
# ``VerletBuild`` (packed once, ``DEMSolver.pack_contact_inputs``). ``WallSet`` and
# ``NeighbourList`` are the contact stages' structs too (re-exported by
# warpdem.stages.structs); they are defined here because the stages import this module. The
# list kernel's candidate test and row ending are shared, as ``wp.func``s, by the hash-grid
# kernel below and the cell-list kernel (warpdem.stages.cell_list), so both searches produce
# the same list from the same candidates.
@wp.struct
class NeighbourList:
    """The Verlet list of :func:`warpdem.kernels.build_neighbour_list` (sorted by index)."""

    count: wp.array(dtype=int)  # entries per sphere
    index: wp.array(dtype=int)  # neighbour sphere indices, ``capacity`` slots per sphere (warpdem.layouts)
    capacity: int  # slots per sphere (``max_neighbours``)
    near_static_wall: wp.array(dtype=int)  # 1: a static wall lies within r_i + skin (query its BVH)


@wp.struct
class WallSet:
    """Triangle-mesh walls with prescribed rigid motion, each looked up in its rest frame."""

    mesh: wp.array(dtype=wp.uint64)  # wp.Mesh id of each wall's rest mesh (BVH)
    world_start: wp.array(dtype=int)  # CSR: the walls of world w are world_index[world_start[w]:world_start[w+1]]
    world_index: wp.array(dtype=int)
    moving: wp.array(dtype=int)  # 1: the wall has a prescribed motion
    material: wp.array(dtype=int)  # material index
    tri_offset: wp.array(dtype=int)  # index of the wall's first triangle among all walls' triangles
    lin_vel: wp.array(dtype=wp.vec3)  # translation velocity v [m/s]
    ang_vel: wp.array(dtype=wp.vec3)  # angular velocity w [rad/s]
    origin: wp.array(dtype=wp.vec3)  # rotation centre c0 at rest [m]
    t_start: wp.array(dtype=float)  # motion window [t_start, t_stop) [s]
    t_stop: wp.array(dtype=float)
    reach: wp.array(dtype=float)  # largest distance of a rest-mesh vertex from the origin c0 [m]


@wp.struct
class ListSpheres:
    """What a list build reads of the spheres: one State's positions and active flags with
    the model's radii, worlds and bodies, and the search distances."""

    position: wp.array(dtype=wp.vec3)  # sphere centre x [m] (the State's ``sphere_x``)
    radius: wp.array(dtype=float)  # sphere radius r [m]
    world: wp.array(dtype=int)  # world index of each sphere
    body: wp.array(dtype=int)  # body index of each sphere
    body_active: wp.array(dtype=int)  # 1: the body is in play (the State's ``body_active``)
    max_radius: float  # largest sphere radius r_max [m]
    skin: float  # Verlet skin [m]: pairs closer than r_i + r_j + skin are listed


@wp.struct
class VerletBuild:
    """What a list build writes: the list, the positions it was built at, the overflow
    counters, and the device flag that requests the build."""

    neighbours: NeighbourList  # the list (``capacity`` = max_neighbours slots per sphere)
    x_at_build: wp.array(dtype=wp.vec3)  # sphere centre at the last build [m]
    overflow: wp.array(dtype=int)  # [0]: entries dropped; [1]: the longest row a sphere needed
    rebuild: wp.array(dtype=int)  # [0] != 0: build now (else every thread returns at once)


@functools.lru_cache(maxsize=None)
def verlet_candidate_function(layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Function":
    """:func:`add_verlet_candidate` for the neighbour list's ``layout``
    (:mod:`warpdem.layouts`), built once per layout."""
    entry = entry_function(layout)  # compiled in: where entry k of sphere i lies

    @wp.func
    def add_verlet_candidate(
        j: int,
        xi: wp.vec3,
        ri: float,
        body_i: int,
        i: int,
        n_kept: int,
        n_dropped: int,
        spheres: ListSpheres,
        out: VerletBuild,
    ):
        """Offer sphere ``j`` to the list row of sphere ``i`` at ``xi`` [m] of radius ``ri`` [m] and
        body ``body_i`` (its ``n_kept`` entries so far, sorted by index). ``j`` is kept if it
        belongs to another, active body and its centre is closer than r_i + r_j + skin [m]; it is
        inserted in index order (so the row does not depend on the order candidates are offered,
        unless the row is full). A full row counts the drop in ``out.overflow[0]``. Returns the
        row's new (kept, dropped) counts."""
        bj = spheres.body[j]
        if bj == body_i or spheres.body_active[bj] == 0:  # removed bodies stay where they left, out of play
            return n_kept, n_dropped
        d = xi - spheres.position[j]
        reach = ri + spheres.radius[j] + spheres.skin
        if wp.dot(d, d) >= reach * reach:
            return n_kept, n_dropped
        cap = out.neighbours.capacity
        if n_kept >= cap:
            # overflow[0]: entries dropped; overflow[1]: the largest list any sphere needed
            wp.atomic_add(out.overflow, 0, 1)
            return n_kept, n_dropped + 1
        # insertion keeps the list sorted by index
        row = out.neighbours.index
        rows = out.neighbours.count.shape[0]
        k = n_kept
        while k > 0 and row[entry(i, k - 1, rows, cap)] > j:
            row[entry(i, k, rows, cap)] = row[entry(i, k - 1, rows, cap)]
            k -= 1
        row[entry(i, k, rows, cap)] = j
        return n_kept + 1, n_dropped

    return add_verlet_candidate


@wp.func
def near_static_wall(xi: wp.vec3, ri: float, skin: float, world: int, walls: WallSet):
    """1 if a triangle of a static wall of ``world`` lies within the box xi +- (r_i + skin) [m]
    (its BVH is then queried each step), else 0."""
    near = int(0)
    ext = wp.vec3(ri + skin, ri + skin, ri + skin)
    for kk in range(walls.world_start[world], walls.world_start[world + 1]):
        k = walls.world_index[kk]
        if walls.moving[k] != 0:
            continue
        mq = wp.mesh_query_aabb(walls.mesh[k], xi - ext, xi + ext)
        tri = int(0)
        if wp.mesh_query_aabb_next(mq, tri):
            near = 1
    return near


@wp.func
def finish_verlet_row(
    i: int,
    xi: wp.vec3,
    ri: float,
    active: int,
    world: int,
    n_kept: int,
    n_dropped: int,
    spheres: ListSpheres,
    walls: WallSet,
    out: VerletBuild,
):
    """Close sphere ``i``'s row: its length, the largest length needed (``out.overflow[1]``, if
    entries were dropped), whether a static wall is near (0 for an inactive sphere) and the
    position [m] the row was built at."""
    out.x_at_build[i] = xi
    out.neighbours.count[i] = n_kept
    if n_dropped > 0:
        wp.atomic_max(out.overflow, 1, n_kept + n_dropped)
    near = int(0)
    if active != 0:
        near = near_static_wall(xi, ri, spheres.skin, world, walls)
    out.neighbours.near_static_wall[i] = near


@functools.lru_cache(maxsize=None)
def build_neighbour_list_kernel(layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Kernel":
    """The hash-grid list kernel (:func:`build_neighbour_list` below) writing the list in
    ``layout`` (:mod:`warpdem.layouts`), built once per layout."""
    add_verlet_candidate = verlet_candidate_function(layout)

    @wp.kernel
    def build_neighbour_list(grid: wp.uint64, spheres: ListSpheres, walls: WallSet, out: VerletBuild):
        """Verlet list from Warp's hash grid ``grid`` (grouped by world): spheres of the same world
        and another body within r_i + r_j + skin, sorted by index (:func:`add_verlet_candidate`);
        and whether a static wall of its world lies within r_i + skin (:func:`near_static_wall`).
        Valid while no sphere moves more than skin / 2. Does nothing unless ``out.rebuild[0]`` is
        set, so the launch can sit unconditionally in a CUDA graph. The cell-list search
        (:mod:`warpdem.stages.cell_list`) builds the same list without the hash grid."""
        if out.rebuild[0] == 0:
            return
        i = wp.tid()
        xi = spheres.position[i]
        ri = spheres.radius[i]
        b = spheres.body[i]
        world = spheres.world[i]
        active = spheres.body_active[b]
        n = int(0)
        n_dropped = int(0)
        if active != 0:
            q = wp.hash_grid_query(grid, xi, ri + spheres.max_radius + spheres.skin, world)
            j = int(0)
            while wp.hash_grid_query_next(q, j):
                n, n_dropped = add_verlet_candidate(j, xi, ri, b, i, n, n_dropped, spheres, out)
        finish_verlet_row(i, xi, ri, active, world, n, n_dropped, spheres, walls, out)

    return build_neighbour_list


@wp.kernel
def finish_build(rebuild: wp.array(dtype=int), builds: wp.array(dtype=int)):
    """Count a list build and clear the request flag."""
    if rebuild[0] != 0:
        builds[0] = builds[0] + 1
        rebuild[0] = 0


@wp.kernel
def flag_moved_spheres(
    sphere_x: wp.array(dtype=wp.vec3),
    x_at_build: wp.array(dtype=wp.vec3),
    half_skin: float,
    rebuild: wp.array(dtype=int),
):
    """Set rebuild[0] = 1 if any sphere moved more than skin / 2 since the last list build."""
    i = wp.tid()
    d = sphere_x[i] - x_at_build[i]
    if wp.dot(d, d) > half_skin * half_skin:
        rebuild[0] = 1


# ----------------------------------------------------------------------------- contacts
# The contact computation (wall contacts, wall forces and wear, particle forces) is staged in
# warpdem.stages, one module per stage, over the packed structs of warpdem.stages.structs.


@wp.kernel
def kinetic_energy(
    body_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.vec3),
    active: wp.array(dtype=int),
    rot: wp.array(dtype=wp.quat),
    v: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=wp.vec3),
    ke_body: wp.array(dtype=float),
):
    """Translational + rotational kinetic energy of each body [J] (0 for a removed body); summed
    per world on the host in body order (:meth:`warpdem.solver.Simulation.kinetic_energy`), so the
    sum is the same on every run (an atomic sum on a GPU differs in the last digits)."""
    b = wp.tid()
    if active[b] == 0:
        ke_body[b] = 0.0
        return
    wb = wp.quat_rotate_inv(rot[b], w[b])
    ke_body[b] = 0.5 * body_mass[b] * wp.dot(v[b], v[b]) + 0.5 * wp.dot(wb, wp.cw_mul(body_inertia[b], wb))


@wp.kernel
def sum_wear_lanes(lanes: wp.array(dtype=float), num_lanes: int, entries: int, out: wp.array(dtype=float)):
    """out[e] = sum over k of lanes[k * entries + e], k = 0 .. num_lanes - 1 in order (the wall
    accumulators' copies, :class:`warpdem.solver.WallStats`)."""
    e = wp.tid()
    total = float(0.0)
    for k in range(num_lanes):
        total = total + lanes[k * entries + e]
    out[e] = total
