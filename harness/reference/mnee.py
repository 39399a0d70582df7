r"""Volumetric path tracer with manifold next-event estimation through smooth dielectrics (``mneevolpath``).

.. list-table::
   :header-rows: 1

   * - Parameter
     - Type
     - Description
   * - max_depth
     - |int|
     - Longest path, counted in segments as in ``volpath`` (-1: unbounded). A manifold
       connection adds two segments (medium vertex -> interface -> light), so with one
       refraction on the camera side ``max_depth = 4`` is single scattering. Default: -1
   * - rr_depth
     - |int|
     - Depth from which Russian roulette may end a path, as in ``volpath``
       (``q = min(max(throughput) * eta^2, 0.95)``). Default: 5
   * - newton_iterations
     - |int|
     - Most Newton iterations (each one ray cast) of one manifold walk. Default: 32
   * - newton_tolerance
     - |float|
     - A walk has converged when the tangential part of the generalized half vector
       ``h = eta wi + wo`` is below this: ``|eta sin(theta_i) - sin(theta_o)|``, Snell's
       law's residual (plus ``1e-6 max(|x1|, 1) / |y - x1|``, the residual that float32
       rounding of ``x1`` causes on the light's side). Default: 1e-5
   * - ratio_tracking_scale
     - |float|
     - Ratio tracking of the transmittance from a medium vertex to the interface uses
       this multiple of the medium's majorant (>= 1). Larger values cost more lookups and
       give less noise; 1 makes the estimate binary in a constant medium. Default: 2
   * - max_crossings
     - |int|
     - Longest chain of refractions a connection follows (1, 3, 5, ... crossings of the
       boundary along the seed segment; 1 is a single refraction), 1 to 9. Default: 5
   * - stats
     - |bool|
     - Add AOV channels per pixel (sums over the path's vertices, averaged over samples,
       :data:`STATS_AOVS`): manifold walks started, walks converged, walks converged into a
       visible, transmissive connection; connections whose seed segment crosses the
       boundary 1, 3, 5, >= 7 times; chains connected; connections lost (not made although
       the path's length allows them) and of those over ``max_crossings``; and the RGB
       light of the lost ones, estimated by their straight seed with every dielectric
       index-matched (exact at eta -> 1), times the path's throughput. Default: false
   * - probe_seeds
     - |int|
     - Diagnostics (with ``stats``): after each walk, this many more walks from random
       seeds; four more AOV channels: vertices where only a probe found a connection, and
       the RGB light of the solutions the main walk missed (not added to the image; a
       lower bound of the energy lost to failed walks and further solutions). Default: 0

What it renders
---------------
The light transport of ``volpath``: delta tracking with null collisions in heterogeneous
media (spectral tracking: the real-collision probability is ``mean(beta sigma_t) /
mean(beta (sigma_t + sigma_n))`` over the colour channels, Kutz et al. 2017, so
that the weights stay bounded in chromatic media), phase-function and BSDF sampling,
next-event estimation from medium vertices and from non-delta surfaces with ratio-tracked
transmittance through null (index-matched) interfaces, emitter hits with multiple
importance sampling, Russian roulette. Camera-side refraction stays as the smooth
``dielectric`` BSDF samples it.

The addition: at a real scattering vertex ``x0`` inside a shape whose BSDF is Mitsuba's
smooth ``dielectric`` (and which has an interior medium), a light with a delta position
(``point``, ``spot``) is connected *through the interface* by manifold next-event
estimation (Hanika, Droske and Fascione, "Manifold Next Event Estimation", EGSR 2015):

1. **Seed**: the point ``x1`` where the straight segment from ``x0`` toward the light
   ``y`` leaves the shape.
2. **Newton walk** on the generalized half-vector constraint (Hanika et al. Sec. 4;
   Jakob and Marschner 2012): with ``wi = (x0 - x1)/|x0 - x1|``, ``wo = (y - x1)/|y - x1|``
   and ``eta = eta_inside / eta_outside``, ``h = eta wi + wo`` must be parallel to the
   interpolated shading normal ``n`` at ``x1``: ``C = (h.s, h.t) = 0`` in a tangent frame
   ``(s, t)`` of ``n`` (not normalised, unlike the paper: see
   :func:`half_vector_constraint`). Its 2x2 derivative with respect to the
   triangle's barycentric parameters ``(u, v)`` (``dp_du, dp_dv`` and the normal's
   ``dn_du, dn_dv`` from ``RayFlags.dNSdUV``) gives the step ``delta = J^-1 C``; the
   tangent-plane point ``x1 - beta (delta_u dp_du + delta_v dp_dv)`` is re-projected onto
   the surface by a ray cast from ``x0`` toward it (so ``x1`` is always the first surface
   point seen from ``x0``). A step that leaves the shape or is not transmissive
   (``wi`` and ``wo`` on the two sides of both normals) is halved; an accepted step
   doubles ``beta`` back toward 1.
3. **Generalized geometry term** (the manifold Jacobian, Hanika et al. Eq. 8): by
   etendue conservation the irradiance at ``x0`` perpendicular to ``wi`` is
   ``E = I T_fresnel Tr eta^2 |n_g . wi| / |x0 - x1|^2 * dA(x1)/dA_perp(y)``, where
   ``dA(x1)/dA_perp(y) = |det dC/d(y_perp)| / |det dC/d(u,v)| * |dp_du x dp_dv|`` is the
   area the solution ``x1`` sweeps when the light moves in the plane perpendicular to
   ``wo`` (implicit function theorem on ``C(x1, y) = 0``). Nothing is clamped, so the
   estimator is unbiased for the solution it finds.
4. **Fresnel transmission** ``1 - F(wo . n, eta)`` (Mitsuba's ``fresnel``, the same
   formula the ``dielectric`` BSDF uses) and the light's intensity toward ``x1``.
5. **Transmittance** from ``x0`` to ``x1`` by ratio tracking (analytic in a
   ``homogeneous`` medium); the segment ``x1 -> y`` must be unoccluded (``ray_test``).
6. **Chains** (issue 26): where the straight seed segment crosses the same shape's boundary
   k = 3, 5, ... <= ``max_crossings`` times (it leaves the object, crosses air, enters
   another part and leaves again), a second walk moves all k crossings at once on the
   block-tridiagonal constraint of Hanika et al. Sec. 4 (:mod:`harness.reference.mnee_chain`:
   Fresnel at every vertex, ratio tracking through every medium segment, the air segments
   unoccluded, the geometry term from the first block of ``(dC/dX)^-1 dC/dy``). Its light
   is added to that of the single-refraction walk: the two are distinct paths.

What is not covered, and how it is handled
------------------------------------------
* **Connections through more crossings than** ``max_crossings``, through another shape,
  or whose chain walk fails: not made; counted and their light estimated with ``stats``
  (:mod:`harness.reference.losses` records both in ``reference.json`` and marks a reference
  whose estimated loss exceeds a quarter of its noise target as not exact). Measured on the
  torus lit through its hole (``benchmarks/mnee_chains.py``, thin medium, eta = 1.0001): a
  fifth of the connections cross three times; without chains the image is 5-8 % dark,
  as much as their estimated light; with chains it agrees with index-matched ``volpath``.
* **Specular chains with a reflection**: light that reaches ``x0`` after a reflection at
  the boundary (inside or outside) followed by refractions toward the light is not
  connected; on a flat interface none exists, on a curved one it is lost (see the
  area-light figures of ``benchmarks/mnee_chains.py --area-limit``).
* **A constraint with several solutions** (near caustics of the interface): the walk
  finds the solution its seed leads to and the others are lost.
* **Walks that fail** (no convergence in ``newton_iterations``, a step below 1e-4, a
  singular Jacobian, a walk that slides off the shape or across a crease of a box): the
  connection contributes nothing.
* Medium vertices *outside* a dielectric, surface vertices inside one, lights without a
  delta position (area lights are reached by phase/BSDF sampling through the delta
  interface, as in ``volpath``), an exterior medium or a surface between the interface and
  the light, rough or textured (``specular_transmittance``) dielectrics: no manifold
  connection (the last one raises). Emission of the medium is not supported.

Every loss listed above makes the image darker, never brighter. Measured on the suite
(``benchmarks/bench_mnee.py --part failures``: 64 x 64, 64 spp, ``stats`` with 4 probe
seeds; shares of the walks started):

=======================  =========  =========  ==========================  ==============================
scene                    converged  connected  a probe connected instead   light the probes found missed
                                               (walk failed, path exists)  (share of the image, R, G, B)
=======================  =========  =========  ==========================  ==============================
jade_backlit_dielectric  0.541      0.541      0.00004                     0.0025, 0.0017, 0.0023
skin_torus_dielectric    0.671      0.500      0.0053                      0.0024, 0.0015, 0.0012
half-space (test 1)      1.000      1.000      0                           0, 0, 0
=======================  =========  =========  ==========================  ==============================

Most walks that do not converge start at vertices that no single refraction reaches at
all (near the surface on the side away from the light, beyond the critical angle): they
carry no light. A converged walk that does not connect ends behind another part of the
object (the torus). The last column is a lower bound of the energy lost to failed walks
and further solutions (at eta = 1.0001 on jade_veins, where the solution is unique, it
reads 9e-5: the floor of the duplicate test); ``--part area-limit`` bounds the whole loss
from the other side with stock ``volpath`` and a shrinking sphere light.

Registration happens once per variant (:func:`register`); ``harness.reference`` uses it for
scenes with ``boundary.kind = "dielectric"`` and ``roughness = 0``.
"""

from harness.reference.llvm import ensure_libllvm

try:  # must precede ``import mitsuba``; a CUDA-only machine may have no LLVM (use_variant checks again)
    ensure_libllvm()
except RuntimeError:
    pass

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from harness.reference import mnee_chain as chain  # noqa: E402

PLUGIN_NAME = "mneevolpath"
DEFAULTS = {"max_depth": -1, "rr_depth": 5, "newton_iterations": 32, "newton_tolerance": 1e-5,
            "ratio_tracking_scale": 2.0, "stats": False, "probe_seeds": 0, "max_crossings": 5}
MIN_STEP = 1e-4            # smallest Newton step factor beta before a walk is given up
MIN_DET = 1e-12            # |det J| below this is treated as singular
POSITION_EPS = 1e-6        # float32 error of a surface point's position (relative to max(|x1|, 1)), ~8 ulp
PLANE_SWITCH = 0.05        # |C| above which a walk step solves the tangent-plane refraction instead
STATS_AOVS = ("mnee_started", "mnee_converged", "mnee_connected",
              "mnee_cross1", "mnee_cross3", "mnee_cross5", "mnee_cross7_more", "mnee_chain_connected", "mnee_lost", "mnee_over_max",
              "mnee_lost_r", "mnee_lost_g", "mnee_lost_b")
#: Bins of :data:`STATS_AOVS`' crossing counts: 1, 3, 5 and 7 or more crossings of the seed segment.
CROSSING_BINS = (1, 3, 5, 7)
PROBE_AOVS = ("mnee_probe_rescued", "mnee_probe_missed_r", "mnee_probe_missed_g", "mnee_probe_missed_b")


# --------------------------------------------------------------------------- vertex math

def _frame(n, dp_du):
    """Unit tangent s (dp_du projected onto the tangent plane of n), t = n x s, and |s~|."""
    s_ = dp_du - n * dr.dot(n, dp_du)
    ls = dr.norm(s_)
    s = s_ / ls
    return s, dr.cross(n, s), s_, ls


def half_vector_constraint(wi, d0, y, p, n, dp_du, dp_dv, dn_du, dn_dv, eta):
    """The constraint ``C = (h.s, h.t)`` at surface point ``p`` and its derivative ``J = dC/d(u, v)``.

    ``wi`` (unit) and ``d0`` give the medium vertex as ``x0 = p + d0 wi``: the walk keeps
    them as the direction and distance of the ray cast from ``x0`` (exact in float32 even
    when ``x0`` lies a hair below the surface, where ``p - x0`` would lose all digits).

    ``h = eta wi + wo`` is the (unnormalised) generalized half vector of a refraction from
    ``y`` (outside, index 1) to ``x0`` (inside, relative index ``eta``); Snell's law
    holds iff its tangential part vanishes, ``C = 0``. ``|C| = |eta sin(theta_i) -
    sin(theta_o)|`` in the plane of incidence. Hanika et al. normalise ``h``; without the
    normalisation the constraint stays well posed as ``eta -> 1`` (where ``|h| -> 0`` on
    every straight line and the normalised form loses all float precision), and the
    geometry term, a ratio of two derivatives of ``C`` at a root, is the same.
    ``(s, t)`` is the tangent frame of the shading normal ``n`` (:func:`_frame`); ``(u, v)``
    the triangle's barycentric parameters, along which the position moves by
    ``dp_du, dp_dv`` and the unit normal by ``dn_du, dn_dv``. Returns
    ``(C0, C1, J00, J01, J10, J11, aux)`` with ``aux`` the quantities the geometry term
    reuses.
    """
    wo_ = y - p
    d1 = dr.norm(wo_)
    wo = wo_ / d1
    h = eta * wi + wo
    s, t, s_, ls = _frame(n, dp_du)

    def d_c(dp, dn):
        # d(wi)/dq = -(I - wi wi^T) dp / d0, likewise wo.
        dh = -eta * (dp - wi * dr.dot(wi, dp)) / d0 - (dp - wo * dr.dot(wo, dp)) / d1
        # dp_du is constant on a triangle; only n moves the frame.
        ds_ = -(dn * dr.dot(n, dp_du) + n * dr.dot(dn, dp_du))
        ds = (ds_ - s * dr.dot(s, ds_)) / ls
        dt = dr.cross(dn, s) + dr.cross(n, ds)
        return dr.dot(dh, s) + dr.dot(h, ds), dr.dot(dh, t) + dr.dot(h, dt)

    j00, j10 = d_c(dp_du, dn_du)
    j01, j11 = d_c(dp_dv, dn_dv)
    aux = {"wi": wi, "wo": wo, "d0": d0, "d1": d1, "s": s, "t": t}
    return dr.dot(h, s), dr.dot(h, t), j00, j01, j10, j11, aux


def light_derivative_det(aux):
    """``|det dC/d(y_perp)|``: the constraint's change when the light moves perpendicular to ``wo``."""
    e1, e2 = mi.coordinate_system(aux["wo"])
    s, t, d1 = aux["s"], aux["t"], aux["d1"]
    # d(h) = d(wo) = (I - wo wo^T) e / d1 = e / d1 for e _|_ wo.
    a00, a10 = dr.dot(e1, s) / d1, dr.dot(e1, t) / d1
    a01, a11 = dr.dot(e2, s) / d1, dr.dot(e2, t) / d1
    return dr.abs(a00 * a11 - a01 * a10)


def generalized_geometry(wi, d0, y, p, n, ng, dp_du, dp_dv, dn_du, dn_dv, eta):
    """``E / (I T Tr)``: irradiance at ``x0`` per unit light intensity through the refraction at ``p``.

    ``eta^2 |n_g . wi| / d0^2 * |det dC/dy_perp| / |det dC/d(u,v)| * |dp_du x dp_dv|``
    (module docstring, step 3), with ``wi, d0`` as in :func:`half_vector_constraint`.
    Tends to ``1 / |y - x0|^2`` when ``eta -> 1``.
    """
    c0, c1, j00, j01, j10, j11, aux = half_vector_constraint(wi, d0, y, p, n, dp_du, dp_dv, dn_du, dn_dv, eta)
    det_j = dr.abs(j00 * j11 - j01 * j10)
    area = dr.norm(dr.cross(dp_du, dp_dv))
    dA_dAy = light_derivative_det(aux) / det_j * area
    g = dr.square(eta) * dr.abs(dr.dot(ng, aux["wi"])) / dr.square(aux["d0"]) * dA_dAy
    return dr.select(det_j > MIN_DET, g, 0.0), aux


def plane_refraction_point(rel, rel_y, n, eta, iterations=12):
    """Exact refraction point through the plane with normal ``n`` through ``x0 + rel``, as an offset from ``x0``.

    ``rel_y = y - x0``. In the plane of incidence the problem is one-dimensional: with
    depth ``a`` of ``x0``, height ``b`` of ``y`` and horizontal distance ``D`` between
    their feet, the point at distance ``r`` from the foot of ``x0`` satisfies Snell's law
    when ``g(r) = eta r / sqrt(r^2 + a^2) - (D - r) / sqrt((D - r)^2 + b^2) = 0``; ``g``
    rises monotonically from ``g(0) < 0`` to ``g(D a / (a + b)) >= 0`` (the straight line's
    crossing), so Newton's method kept inside a shrinking bracket converges. Returns
    ``(offset, valid)``; invalid when ``x0`` is not below or ``y`` not above the plane.
    """
    a = dr.dot(rel, n)
    b = dr.dot(rel_y, n) - a
    horiz = rel_y - dr.dot(rel_y, n) * n
    big_d = dr.norm(horiz)
    e = horiz / dr.maximum(big_d, 1e-30)
    # Start from the straight line's direction bent by Snell's law at x0's depth (exact for a << b).
    r_straight = big_d * a / dr.maximum(a + b, 1e-30)
    lo, hi = mi.Float(0.0), mi.Float(r_straight)
    sin_o = big_d / dr.sqrt(dr.square(big_d) + dr.square(a + b))
    sin_i = dr.minimum(sin_o / eta, 0.999999)
    r = dr.minimum(a * sin_i / dr.sqrt(1.0 - dr.square(sin_i)), r_straight)
    for _ in range(iterations):
        q0 = dr.sqrt(dr.square(r) + dr.square(a))
        q1 = dr.sqrt(dr.square(big_d - r) + dr.square(b))
        g = eta * r / q0 - (big_d - r) / q1
        dg = eta * dr.square(a) / (q0 * q0 * q0) + dr.square(b) / (q1 * q1 * q1)
        lo = dr.select(g < 0, r, lo)
        hi = dr.select(g < 0, hi, r)
        r_newton = r - g / dg
        r = dr.select((r_newton > lo) & (r_newton < hi), r_newton, 0.5 * (lo + hi))
    return a * n + r * e, (a > 0) & (b > 0)


def _index_spectrum(spec, channel):
    return dr.select(channel == 0, spec[0], dr.select(channel == 1, spec[1], spec[2]))


def _mis(a, b):
    """Power heuristic (exponent 2), 0 where both are 0."""
    a2, b2 = dr.square(a), dr.square(b)
    return dr.select(a2 + b2 > 0, a2 / (a2 + b2), 0.0)


class _Vertex:
    """The surface data one manifold walk carries: position, normals and their partials, shape id."""

    FIELDS = ("p", "n", "ng", "dp_du", "dp_dv", "dn_du", "dn_dv")

    @staticmethod
    def of(si):
        return (mi.Point3f(si.p), mi.Vector3f(si.sh_frame.n), mi.Vector3f(si.n), mi.Vector3f(si.dp_du),
                mi.Vector3f(si.dp_dv), mi.Vector3f(si.dn_du), mi.Vector3f(si.dn_dv))


WALK_FLAGS = chain.WALK_FLAGS
MAX_SEGMENT_HITS = 64      # the straight seed segment is followed through at most this many surfaces


# --------------------------------------------------------------------------- the integrator

class MNEEVolpathIntegrator(mi.SamplingIntegrator):
    """Volumetric path tracer with manifold next-event estimation; see the module docstring."""

    def __init__(self, props):
        mi.SamplingIntegrator.__init__(self, props)
        get = lambda k: props.get(k, DEFAULTS[k])  # noqa: E731
        max_depth = int(get("max_depth"))
        if max_depth < -1 or max_depth == 0:
            raise ValueError(f"{PLUGIN_NAME}: max_depth = {max_depth} must be -1 (unbounded) or >= 1")
        self.max_depth = 0xFFFFFFFF if max_depth == -1 else max_depth
        self.rr_depth = int(get("rr_depth"))
        if self.rr_depth < 1:
            raise ValueError(f"{PLUGIN_NAME}: rr_depth = {self.rr_depth} must be >= 1")
        self.newton_iterations = int(get("newton_iterations"))
        if self.newton_iterations < 1:
            raise ValueError(f"{PLUGIN_NAME}: newton_iterations = {self.newton_iterations} must be >= 1")
        self.newton_tolerance = float(get("newton_tolerance"))
        if not 0 < self.newton_tolerance < 0.1:
            raise ValueError(f"{PLUGIN_NAME}: newton_tolerance = {self.newton_tolerance} must lie in (0, 0.1)")
        self.ratio_tracking_scale = float(get("ratio_tracking_scale"))
        if not self.ratio_tracking_scale >= 1.0:
            raise ValueError(f"{PLUGIN_NAME}: ratio_tracking_scale = {self.ratio_tracking_scale} must be >= 1")
        self.stats = bool(get("stats"))
        self.probe_seeds = int(get("probe_seeds"))
        if self.probe_seeds < 0 or (self.probe_seeds and not self.stats):
            raise ValueError(f"{PLUGIN_NAME}: probe_seeds = {self.probe_seeds} must be >= 0 and needs stats = true")
        self.max_crossings = int(get("max_crossings"))
        if not 1 <= self.max_crossings <= chain.MAX_CROSSINGS_LIMIT:
            raise ValueError(f"{PLUGIN_NAME}: max_crossings = {self.max_crossings} must lie in "
                             f"[1, {chain.MAX_CROSSINGS_LIMIT}]")
        self._eta_table = None

    def aov_names(self):
        if not self.stats:
            return []
        return list(STATS_AOVS) + (list(PROBE_AOVS) if self.probe_seeds else [])

    def to_string(self):
        return (f"MNEEVolpathIntegrator[max_depth = {self.max_depth}, rr_depth = {self.rr_depth}, "
                f"newton_iterations = {self.newton_iterations}, newton_tolerance = {self.newton_tolerance}]")

    # ------------------------------------------------------------------ scene tables

    def _prepare(self, scene):
        """Relative index of refraction per shape (registry id), 0 where no manifold connection applies.

        Built at every ``sample`` call (a handful of shapes): holding on to the scene would
        tie the integrator's lifetime to it.
        """
        ids, etas = [0], [0.0]
        for shape in scene.shapes():
            bsdf = shape.bsdf()
            if bsdf is None or bsdf.class_name() != "SmoothDielectric" or shape.interior_medium() is None:
                continue
            params = mi.traverse(bsdf)
            if any(k.startswith("specular_transmittance") for k in params.keys()):
                raise ValueError(f"{PLUGIN_NAME}: shape {shape.id()!r}: a dielectric with specular_transmittance "
                                 "is not supported by the manifold connection; remove the parameter")
            ids.append(int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0]))
            etas.append(float(params["eta"]))
        table = dr.zeros(mi.Float, max(ids) + 1)
        dr.scatter(table, mi.Float(etas), mi.UInt32(ids))
        self._eta_table = table

    def _shape_eta(self, shape, active):
        sid = dr.reinterpret_array(mi.UInt32, shape)
        ok = active & (sid < dr.width(self._eta_table))
        return dr.gather(mi.Float, self._eta_table, sid, ok)

    # ------------------------------------------------------------------ transmittance

    @dr.syntax
    def _ratio_track(self, medium, origin, target, sampler, active):
        """Transmittance of ``medium`` along the straight segment origin -> target (no surfaces on it).

        Homogeneous media: ``exp(-sigma_t d)``. Otherwise ratio tracking (Novak et al. 2014)
        with the majorant ``ratio_tracking_scale * max(majorant)``: tentative collisions at
        that rate, each multiplying the estimate by ``1 - sigma_t(x) / majorant``.
        """
        active = mi.Bool(active) & (medium != None)  # noqa: E711 (Dr.Jit pointer comparison)
        d = target - origin
        dist = dr.norm(d)
        direction = d / dr.maximum(dist, 1e-30)
        tr = mi.Spectrum(1.0)
        probe = dr.zeros(mi.MediumInteraction3f)
        probe.p = mi.Point3f(origin)
        homogeneous = active & medium.is_homogeneous()
        _, _, sigma_t0 = medium.get_scattering_coefficients(probe, homogeneous)
        tr[homogeneous] = dr.exp(-sigma_t0 * dist)
        tracking = active & ~homogeneous
        mu = self.ratio_tracking_scale * dr.max(medium.get_majorant(probe, tracking))
        tracking &= mu > 0
        t = mi.Float(0.0)
        while dr.hint(tracking, label="mnee ratio tracking"):
            t += -dr.log(1.0 - sampler.next_1d(tracking)) / mu
            tracking &= t < dist
            probe.p = dr.fma(direction, t, origin)
            _, _, sigma_t = medium.get_scattering_coefficients(probe, tracking)
            tr[tracking] *= dr.maximum(1.0 - sigma_t / mu, 0.0)
            tracking &= dr.any(tr > 0.0)
        return tr

    @dr.syntax
    def _transmittance_to(self, scene, sampler, ref, target, medium, active):
        """Transmittance from interaction ``ref`` to point ``target`` through null interfaces and media.

        A surface whose BSDF is not null (``eval_null_transmission`` = 0, e.g. a dielectric)
        blocks the segment.
        """
        active = mi.Bool(active)
        medium = dr.select(active, medium, dr.zeros(mi.MediumPtr))
        ray = ref.spawn_ray_to(target)
        remaining = mi.Float(ray.maxt)
        tr = mi.Spectrum(1.0)
        while dr.hint(active, label="mnee shadow segment"):
            ray.maxt = remaining
            si = scene.ray_intersect(ray, mi.RayFlags.All, active)
            hit = active & si.is_valid()
            seg = dr.select(hit, si.t, remaining)
            tr[active] *= self._ratio_track(medium, ray.o, ray(seg), sampler, active)
            bsdf = si.bsdf(ray)
            tr[hit] *= bsdf.eval_null_transmission(si, hit)
            active = hit & dr.any(tr > 0.0)
            medium[active & si.is_medium_transition()] = si.target_medium(ray.d)
            remaining -= seg
            ray[active] = si.spawn_ray(ray.d)
        return tr

    @dr.syntax
    def _straight_through(self, scene, sampler, ref, target, medium, shape_id, transmittance, active):
        """Follow the straight seed segment ``ref -> target`` through every surface on it.

        Returns ``(crossings, same_shape, tr)``: how many manifold-eligible dielectric
        surfaces it crosses, whether all of them belong to ``shape_id``, and (where
        ``transmittance``) the transmittance along it with every such dielectric treated as
        index-matched (media ratio-tracked, other surfaces' null transmission): at eta ->
        1 the straight segment is the exact connection, so ``I tr / r^2`` is the measured
        estimate of the light a connection that is not made would carry.
        """
        active = mi.Bool(active)
        medium = dr.select(active, medium, dr.zeros(mi.MediumPtr))
        ray = ref.spawn_ray_to(target)
        remaining = mi.Float(ray.maxt)
        tr = mi.Spectrum(1.0)
        crossings = mi.UInt32(0)
        same = mi.Bool(True)
        hits = mi.UInt32(0)
        while dr.hint(active, label="mnee straight seed"):
            ray.maxt = remaining
            si = scene.ray_intersect(ray, mi.RayFlags.All, active)
            hit = active & si.is_valid()
            seg = dr.select(hit, si.t, remaining)
            if transmittance:
                tr[active] *= self._ratio_track(medium, ray.o, ray(seg), sampler, active)
            dielectric = hit & (self._shape_eta(si.shape, hit) > 0)
            crossings[dielectric] += 1
            same[dielectric & (dr.reinterpret_array(mi.UInt32, si.shape) != shape_id)] = False
            other = hit & ~dielectric
            bsdf = si.bsdf(ray)
            tr[other] *= bsdf.eval_null_transmission(si, other)
            hits += 1
            active = hit & (dielectric | dr.any(tr > 0.0)) & (hits < MAX_SEGMENT_HITS)
            medium[active & si.is_medium_transition()] = si.target_medium(ray.d)
            remaining -= seg
            ray[active] = si.spawn_ray(ray.d)
        return crossings, same, tr

    # ------------------------------------------------------------------ manifold walk

    @dr.syntax
    def _walk(self, scene, x0, y, si0, omega0, eta, active):
        """Newton walk on the half-vector constraint from the seed ``si0`` (hit along ``omega0`` from ``x0``).

        The iterate is the direction ``omega`` of the ray from ``x0`` and the distance
        ``dist`` to its hit (so ``x1 = x0 + dist omega`` without cancellation); a Newton
        step ``delta`` in the tangent plane turns it into ``normalize(dist omega - beta
        delta)``. Far from a solution (``|C| > PLANE_SWITCH``, typically a vertex just
        below the surface whose straight segment leaves it at a grazing angle) the step
        goes to the exact refraction point in the current tangent plane
        (:func:`plane_refraction_point`) instead; close to it Newton converges
        quadratically. Returns ``(converged, vertex, omega, dist, iterations, residual)``.
        """
        p, n, ng, dp_du, dp_dv, dn_du, dn_dv = _Vertex.of(si0)
        omega = mi.Vector3f(omega0)
        dist = mi.Float(si0.t)
        shape_id = dr.reinterpret_array(mi.UInt32, si0.shape)
        rel_y = y - x0
        beta = mi.Float(1.0)                     # Newton step factor (halved on a rejected step)
        iteration = mi.UInt32(0)
        converged = mi.Bool(False)
        walking = mi.Bool(active)
        residual = mi.Float(dr.inf)
        tol = self.newton_tolerance
        while dr.hint(walking, label="mnee newton walk"):
            c0, c1, j00, j01, j10, j11, aux = half_vector_constraint(-omega, dist, y, p, n, dp_du, dp_dv,
                                                                     dn_du, dn_dv, eta)
            c2 = dr.square(c0) + dr.square(c1)
            det = j00 * j11 - j01 * j10
            du = (j11 * c0 - j01 * c1) / det
            dv = (j00 * c1 - j10 * c0) / det
            step = du * dp_du + dv * dp_dv
            # The light side's float32 rounding of x1 bounds the residual from below.
            floor = POSITION_EPS * dr.maximum(dr.max(dr.abs(p)), 1.0) / aux["d1"]
            done = walking & (dr.sqrt(c2) < tol + floor)
            converged |= done
            residual[walking] = dr.sqrt(c2)
            walking &= ~done & (iteration < self.newton_iterations)
            rel = dist * omega - beta * step
            far = c2 > PLANE_SWITCH * PLANE_SWITCH
            plane_rel, plane_ok = plane_refraction_point(dist * omega, rel_y, n, eta)
            rel[far] = plane_rel
            walking &= dr.select(far, plane_ok, dr.abs(det) > MIN_DET)
            ray = mi.Ray3f(x0, dr.normalize(rel))
            ray.maxt = 2.0 * dr.norm(rel)
            si = scene.ray_intersect(ray, WALK_FLAGS, walking)
            wo = dr.normalize(y - si.p)
            ok = (walking & si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == shape_id)
                  & (dr.dot(si.n, ray.d) > 0) & (dr.dot(si.n, wo) > 0)
                  & (dr.dot(si.sh_frame.n, ray.d) > 0) & (dr.dot(si.sh_frame.n, wo) > 0))
            p[ok] = si.p
            n[ok] = si.sh_frame.n
            ng[ok] = si.n
            dp_du[ok] = si.dp_du
            dp_dv[ok] = si.dp_dv
            dn_du[ok] = si.dn_du
            dn_dv[ok] = si.dn_dv
            omega[ok] = ray.d
            dist[ok] = si.t
            beta = dr.select(ok | far, dr.minimum(1.0, 2.0 * beta), 0.5 * beta)
            walking &= ok | ~far                 # a plane step that leaves the shape ends the walk
            iteration += 1
            walking &= beta >= MIN_STEP
        return converged, (p, n, ng, dp_du, dp_dv, dn_du, dn_dv), omega, dist, iteration, residual

    def _manifold_value(self, scene, sampler, x0, y, si_seed, omega_seed, eta, emitter, u2, sel_weight, medium,
                        active):
        """One walk from a seed and, where it ends in a visible transmissive solution, its light at ``x0``.

        Returns ``(converged, connected, value, direction, x1)``: ``value`` is the
        irradiance at ``x0`` along ``direction`` divided by the light's selection density
        (``I T Tr G / p_select``, module docstring steps 3-5).
        """
        converged, vertex, omega, dist, _, _ = self._walk(scene, x0, y, si_seed, omega_seed, eta, active)
        p, n, ng, dp_du, dp_dv, dn_du, dn_dv = vertex
        g, aux = generalized_geometry(-omega, dist, y, p, n, ng, dp_du, dp_dv, dn_du, dn_dv, eta)
        wo = aux["wo"]
        conn = converged & (g > 0) & (dr.dot(n, wo) > 0) & (dr.dot(ng, wo) > 0)
        it1 = dr.zeros(mi.Interaction3f)
        it1.p = p
        it1.n = ng
        it1.t = 0.0
        conn &= ~scene.ray_test(it1.spawn_ray_to(y), conn)
        ds1, em1 = emitter.sample_direction(it1, u2, conn)
        intensity = em1 * dr.square(ds1.dist)         # point/spot value is I(w) / r^2 (pdf 1)
        fresnel_r, _, _, _ = mi.fresnel(dr.dot(n, wo), eta)
        tr = self._ratio_track(medium, x0, p, sampler, conn)
        value = dr.select(conn, sel_weight * intensity * (1.0 - fresnel_r) * g * tr, 0.0)
        return converged, conn, value, omega, p

    def _chain_value(self, scene, sampler, x0, y, direction, eta, shape_id, k, emitter, u2, sel_weight, medium,
                     active):
        """A k-vertex chain (:mod:`harness.reference.mnee_chain`) from the straight seed, and its light at ``x0``.

        Returns ``(connected, value, direction)``: ``value = I G prod(1 - F_i) prod Tr_j /
        p_select`` (``mnee_chain`` docstring) along ``direction`` from ``x0``.
        """
        verts, dist, ok = chain.seed_chain(scene, x0, direction, k, shape_id, active)
        conv, verts, omega, dist = chain.walk_chain(scene, x0, y, verts, direction, dist, eta, shape_id,
                                                    self.newton_iterations, self.newton_tolerance, ok)
        g, _, aux = chain.chain_geometry(omega, dist, verts, y, eta)
        conn = conv & (g > 0)
        it = dr.zeros(mi.Interaction3f)
        it.p, it.n, it.t = verts[-1][0], verts[-1][2], 0.0
        conn &= ~scene.ray_test(it.spawn_ray_to(y), conn)    # the last air segment (the others: the walk's casts)
        ds1, em1 = emitter.sample_direction(it, u2, conn)
        intensity = em1 * dr.square(ds1.dist)
        tr = self._ratio_track(medium, x0, verts[0][0], sampler, conn)
        for i in range(1, k - 1, 2):                          # inside the other parts: entry i -> exit i + 1
            tr *= self._ratio_track(medium, verts[i][0], verts[i + 1][0], sampler, conn)
        fresnel_t = chain.chain_fresnel(verts, aux, eta)
        value = dr.select(conn, sel_weight * intensity * fresnel_t * g * tr, 0.0)
        return conn, value, omega

    def _connect(self, scene, sampler, mei, medium, active, depth, phase_value):
        """Next-event estimation from medium vertex ``mei``: manifold connection or a straight one.

        A connection through k crossings adds k + 1 segments to the path's ``depth``; where
        they do not fit into ``max_depth``, an eligible vertex gets no connection of that
        length (a straight one would be blocked by the interface). ``phase_value(direction)`` is
        the phase function toward a direction (used by the probe seeds). Returns
        ``(value, direction, pdf, stats)``: the light arriving at ``mei`` along
        ``direction`` divided by its sampling density (times the phase function gives the
        contribution), the solid-angle pdf used for MIS (0 for delta lights), the light and
        direction of a chain through 3, 5, ... crossings (found where the seed segment
        crosses that many times, up to ``max_crossings``; a second, distinct path, added to
        the first), and the :data:`STATS_AOVS` of this vertex (counts, then the lost light
        times the phase function).
        """
        idx, sel_weight, _ = scene.sample_emitter(sampler.next_1d(active), active)
        emitter = dr.gather(mi.EmitterPtr, scene.emitters_dr(), idx, active)
        u2 = sampler.next_2d(active)
        ds, em_val = emitter.sample_direction(mei, u2, active)
        active &= ds.pdf > 0
        delta_pos = mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)

        # ---- seed: where the straight segment toward the light leaves the object
        seed_ray = mi.Ray3f(mei.p, ds.d)
        seed_ray.maxt = ds.dist
        si0 = scene.ray_intersect(seed_ray, WALK_FLAGS, active)
        eta = self._shape_eta(si0.shape, active & si0.is_valid())
        eligible = active & delta_pos & si0.is_valid() & (eta > 0) & (dr.dot(si0.n, ds.d) > 0)
        manifold = eligible & (depth + 1 < self.max_depth)
        straight = active & ~eligible

        # ---- straight connection (index-matched or open path): ratio-tracked shadow segment
        tr = self._transmittance_to(scene, sampler, mei, ds.p, medium, straight)
        value = dr.select(straight, em_val * sel_weight * tr, 0.0)
        direction = mi.Vector3f(ds.d)
        pdf = dr.select(ds.delta, 0.0, ds.pdf / sel_weight)

        # ---- manifold connection through the interface
        y = ds.p
        converged, conn, m_value, omega, x1 = self._manifold_value(scene, sampler, mei.p, y, si0, ds.d, eta, emitter,
                                                                   u2, sel_weight, medium, manifold)
        value[conn] = m_value
        direction[conn] = omega
        pdf[eligible] = 0.0

        # ---- chains: the seed segment leaves, re-enters and leaves again (k = 3, 5, ... crossings)
        shape_id = dr.reinterpret_array(mi.UInt32, si0.shape)
        crossings, same, tr_straight = self._straight_through(scene, sampler, mei, y, medium, shape_id, self.stats,
                                                              manifold)
        chain_value = mi.Spectrum(0.0)
        chain_dir = mi.Vector3f(ds.d)
        chain_conn = mi.Bool(False)
        for k in range(3, self.max_crossings + 1, 2):
            lane = manifold & same & (crossings == k) & (depth + k < self.max_depth)
            conn_k, value_k, omega_k = self._chain_value(scene, sampler, mei.p, y, ds.d, eta, shape_id, k, emitter,
                                                         u2, sel_weight, medium, lane)
            chain_value[conn_k] = value_k
            chain_dir[conn_k] = omega_k
            chain_conn |= conn_k
        stats = []
        if self.stats:
            # Not made although the path's length allows it: over max_crossings, another shape on
            # the way, or a chain walk that failed (depth-limited vertices are not losses).
            lost = manifold & (crossings > 1) & (depth + crossings < self.max_depth) & ~chain_conn
            over = lost & (crossings > self.max_crossings)
            lost_light = dr.select(lost, em_val * sel_weight * tr_straight * phase_value(ds.d, lost), 0.0)
            bins = [crossings == b for b in CROSSING_BINS[:-1]] + [crossings >= CROSSING_BINS[-1]]
            stats = ([dr.select(manifold, 1.0, 0.0), dr.select(converged, 1.0, 0.0), dr.select(conn, 1.0, 0.0)]
                     + [dr.select(manifold & b, 1.0, 0.0) for b in bins]
                     + [dr.select(chain_conn, 1.0, 0.0), dr.select(lost, 1.0, 0.0), dr.select(over, 1.0, 0.0)]
                     + [lost_light[0], lost_light[1], lost_light[2]])
        if self.probe_seeds:
            stats += self._probe(scene, sampler, mei.p, y, ds.d, eta, emitter, u2, sel_weight, medium, manifold,
                                 conn, x1, phase_value)
        return value, direction, pdf, (chain_value, chain_dir), stats

    def _probe(self, scene, sampler, x0, y, to_light, eta, emitter, u2, sel_weight, medium, active, conn, x1,
               phase_value):
        """Diagnostics: walks from ``probe_seeds`` random seeds; the light of the solutions the main walk missed.

        Each seed is the first surface point along a direction drawn uniformly from the
        hemisphere around the direction to the light. A converged, connected solution more
        than ``1e-4 max(|x1|, 1)`` away from every solution found before (the main one
        included) is new: its contribution (times the phase function) is added to the
        missed light, a lower bound of the energy the single walk loses to failed walks
        and further solutions. Returns the ``mnee_probe_*`` AOVs.
        """
        frame = mi.Frame3f(to_light)
        found = [(x1, conn)]
        missed = mi.Spectrum(0.0)
        rescued = mi.Bool(False)
        for _ in range(self.probe_seeds):
            d = frame.to_world(mi.warp.square_to_uniform_hemisphere(sampler.next_2d(active)))
            si = scene.ray_intersect(mi.Ray3f(x0, d), WALK_FLAGS, active)
            seeded = active & si.is_valid() & (self._shape_eta(si.shape, active & si.is_valid()) > 0)
            _, conn_k, value_k, omega_k, x_k = self._manifold_value(scene, sampler, x0, y, si, d, eta, emitter, u2,
                                                                  sel_weight, medium, seeded)
            new = mi.Bool(conn_k)
            for x_j, ok_j in found:
                new &= ~ok_j | (dr.norm(x_k - x_j) > 1e-4 * dr.maximum(dr.max(dr.abs(x_k)), 1.0))
            missed[new] += value_k * phase_value(omega_k, new)
            rescued |= new & ~conn
            found.append((x_k, conn_k))
        return [dr.select(rescued, 1.0, 0.0), missed[0], missed[1], missed[2]]

    # ------------------------------------------------------------------ path tracing

    @dr.syntax
    def sample(self, scene, sampler, ray_, medium=None, active=True):
        self._prepare(scene)
        ray = mi.Ray3f(ray_)
        active = mi.Bool(active)
        medium = dr.zeros(mi.MediumPtr) if medium is None else mi.MediumPtr(medium)
        L = mi.Spectrum(0.0)                       # radiance
        beta = mi.Spectrum(1.0)                    # throughput
        eta = mi.Float(1.0)                        # accumulated relative index (Russian roulette)
        depth = mi.UInt32(0)                       # segments so far
        si = dr.zeros(mi.SurfaceInteraction3f)
        needs_intersection = mi.Bool(True)
        prev_it = dr.zeros(mi.Interaction3f)       # last non-null vertex, for MIS of emitter hits
        prev_pdf = mi.Float(1.0)
        specular_chain = mi.Bool(True)             # no MIS for hits after the camera / a delta vertex
        valid_ray = mi.Bool(False)
        counters = [mi.Float(0.0) for _ in self.aov_names()]
        # One channel drives free-flight sampling (Mitsuba's RGB convention).
        channel = mi.UInt32(dr.minimum(3.0 * sampler.next_1d(active), 2.0))

        while dr.hint(active, label="mneevolpath"):
            active &= dr.any(beta != 0.0)

            # ---------------- Russian roulette
            q = dr.minimum(dr.max(beta) * dr.square(eta), 0.95)
            roulette = active & (depth >= self.rr_depth)
            active &= (sampler.next_1d(active) < q) | ~roulette
            beta[roulette] *= dr.rcp(q)

            in_medium = active & (medium != None)  # noqa: E711
            on_surface = active & ~in_medium

            # ---------------- free flight (delta tracking with null collisions)
            mei = medium.sample_interaction(ray, sampler.next_1d(in_medium), channel, in_medium)
            ray.maxt[in_medium & medium.is_homogeneous() & mei.is_valid()] = mei.t
            isect = needs_intersection & in_medium
            si[isect] = scene.ray_intersect(ray, isect)
            needs_intersection &= ~in_medium
            mei.t[in_medium & (si.t < mei.t)] = dr.inf
            tr, ff_pdf = medium.transmittance_eval_pdf(mei, si, in_medium)
            tr_pdf = _index_spectrum(ff_pdf, channel)
            beta[in_medium] *= dr.select(tr_pdf > 0, tr / tr_pdf, 0.0)
            escaped = in_medium & ~mei.is_valid()
            in_medium &= mei.is_valid()
            # Spectral tracking with history-aware probabilities (Kutz et al. 2017, Sec. 4): the
            # channel sum of the throughput never grows, so chromatic media stay free of fireflies.
            w_real = dr.mean(beta * mei.sigma_t)
            w_null = dr.mean(beta * mei.sigma_n)
            p_real = w_real / (w_real + w_null)
            null = in_medium & (sampler.next_1d(in_medium) >= p_real)
            real = in_medium & ~null
            beta[null] *= mei.sigma_n / (1.0 - p_real)
            beta[real] *= mei.sigma_s / p_real
            ray.o[null] = mei.p
            si.t[null] = si.t - mei.t
            depth[real] += 1
            active &= depth < self.max_depth
            real &= active

            # ---------------- next-event estimation from the medium vertex (manifold or straight)
            phase_ctx = mi.PhaseFunctionContext(sampler)
            phase = mei.medium.phase_function()
            nee = real & mei.medium.use_emitter_sampling()
            # A manifold connection through k crossings needs k + 1 more segments, a straight one one.
            value, direction, nee_pdf, (chain_value, chain_dir), stats = self._connect(
                scene, sampler, mei, medium, nee, depth, lambda w, m: phase.eval_pdf(phase_ctx, mei, w, m)[0])
            # Per-vertex counts; the lost light and the probes' missed light (AOVs *_r, *_g, *_b)
            # carry the throughput.
            for k, name in enumerate(self.aov_names()):
                weight = beta["rgb".index(name[-1])] if name[-2:] in ("_r", "_g", "_b") else 1.0
                counters[k] += dr.select(nee, stats[k] * weight, 0.0)
            phase_val, phase_pdf = phase.eval_pdf(phase_ctx, mei, direction, nee)
            L[nee] += beta * phase_val * value * dr.select(nee_pdf > 0, _mis(nee_pdf, phase_pdf), 1.0)
            chained = nee & dr.any(chain_value != 0.0)
            phase_chain, _ = phase.eval_pdf(phase_ctx, mei, chain_dir, chained)
            L[chained] += beta * phase_chain * chain_value

            # ---------------- phase-function sampling
            wo, phase_w, phase_pdf = phase.sample(phase_ctx, mei, sampler.next_1d(real), sampler.next_2d(real), real)
            real &= phase_pdf > 0
            beta[real] *= phase_w
            ray[real] = mei.spawn_ray(wo)
            needs_intersection |= real
            prev_it[real] = mei
            prev_pdf[real] = phase_pdf
            valid_ray |= real
            specular_chain[real] = ~mei.medium.use_emitter_sampling()

            # ---------------- surfaces
            on_surface |= escaped
            isect = on_surface & needs_intersection
            si[isect] = scene.ray_intersect(ray, isect)

            emitter = si.emitter(scene)
            hit_emitter = on_surface & (emitter != None)  # noqa: E711
            ds = mi.DirectionSample3f(scene, si, prev_it)
            em_pdf = scene.pdf_emitter_direction(prev_it, ds, hit_emitter & ~specular_chain)
            w_hit = dr.select(specular_chain, 1.0, _mis(prev_pdf, em_pdf))
            L[hit_emitter] += beta * w_hit * emitter.eval(si, hit_emitter)

            on_surface &= si.is_valid()
            bsdf_ctx = mi.BSDFContext()
            bsdf = si.bsdf(ray)

            # next-event estimation from a non-delta surface (straight connections only)
            nee_s = on_surface & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth) & (depth + 1 < self.max_depth)
            idx, sel_weight, _ = scene.sample_emitter(sampler.next_1d(nee_s), nee_s)
            emitter_s = dr.gather(mi.EmitterPtr, scene.emitters_dr(), idx, nee_s)
            ds_s, em_s = emitter_s.sample_direction(si, sampler.next_2d(nee_s), nee_s)
            nee_s &= ds_s.pdf > 0
            medium_s = dr.select(si.is_medium_transition(), si.target_medium(ds_s.d), medium)
            tr_s = self._transmittance_to(scene, sampler, si, ds_s.p, medium_s, nee_s)
            bsdf_val, bsdf_pdf = bsdf.eval_pdf(bsdf_ctx, si, si.to_local(ds_s.d), nee_s)
            w_s = dr.select(ds_s.delta, 1.0, _mis(ds_s.pdf / sel_weight, bsdf_pdf))
            L[nee_s] += beta * bsdf_val * em_s * sel_weight * tr_s * w_s

            # BSDF sampling (camera-side refraction included)
            bs, bsdf_w = bsdf.sample(bsdf_ctx, si, sampler.next_1d(on_surface), sampler.next_2d(on_surface),
                                     on_surface)
            on_surface &= bs.pdf > 0
            beta[on_surface] *= bsdf_w
            eta[on_surface] *= bs.eta
            ray[on_surface] = si.spawn_ray(si.to_world(bs.wo))
            needs_intersection |= on_surface
            non_null = on_surface & ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
            depth[non_null] += 1
            prev_it[non_null] = si
            prev_pdf[non_null] = bs.pdf
            valid_ray |= non_null
            specular_chain[non_null] = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            crossing = on_surface & si.is_medium_transition()
            medium[crossing] = si.target_medium(ray.d)
            active &= on_surface | in_medium

        return L, valid_ray, counters


_REGISTERED = set()


def register():
    """Register ``mneevolpath`` for the active Mitsuba variant (once per variant)."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError(f"{PLUGIN_NAME}: set a Mitsuba variant (mi.set_variant) before registering the plugin")
    if variant not in _REGISTERED:
        mi.register_integrator(PLUGIN_NAME, lambda props: MNEEVolpathIntegrator(props))
        _REGISTERED.add(variant)
    return PLUGIN_NAME
