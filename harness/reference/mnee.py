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
   * - sms_trials
     - |int|
     - Specular manifold sampling (:mod:`harness.reference.mnee_sms`, Zeltner et al. 2020) of the
       connections the straight seed misses: the most Bernoulli trials that weigh one sampled
       solution (0: off), 0 to 4096. ``[boundary] sms_trials`` of a scene sets it. Default: 0
   * - sms_chains
     - |string|
     - With ``sms_trials``: the chains sampled, from the medium vertex: ``T`` a refraction, ``R``
       a reflection inside, ``r`` one off the outside, comma-separated. Default: ``T,RT,Tr,TTT``
   * - sms_only
     - |bool|
     - With ``sms_trials``: the image holds only the light of the sampled solutions (7.), nothing
       else. Their light is added to the rest's as distinct paths (no weights shared), so an image
       rendered with ``sms_trials = 0`` plus one rendered with ``sms_only`` has the expectation of the
       whole: the reference renders the costly sampled part with fewer samples than the rest
       (:class:`harness.reference.jobs.PassSpec`). Default: false
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
6. **Chains**: where the straight seed segment crosses the same shape's boundary
   k = 3, 5, ... <= ``max_crossings`` times (it leaves the object, crosses air, enters
   another part and leaves again), a second walk moves all k crossings at once on the
   block-tridiagonal constraint of Hanika et al. Sec. 4 (:mod:`harness.reference.mnee_chain`:
   Fresnel at every vertex, ratio tracking through every medium segment, the air segments
   unoccluded, the geometry term from the first block of ``(dC/dX)^-1 dC/dy``). Its light
   is added to that of the single-refraction walk: the two are distinct paths.
7. **Specular manifold sampling** (``sms_trials`` > 0; :mod:`harness.reference.mnee_sms`): from random
   seeds, further solutions of the single refraction and of the three-crossing chain, and chains
   with a reflection vertex (``sms_chains``), each weighted by Bernoulli trials that estimate the
   inverse of the probability that a random seed finds it (Zeltner, Georgiev and Jakob 2020). Also
   added: distinct paths.

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
  connected by the straight seed; with ``sms_trials`` > 0 the chains named in ``sms_chains``
  are sampled (7.); the others are lost.
* **A constraint with several solutions** (near caustics of the interface, or where the
  straight seed leads to a solution that another part of the object occludes while another
  one is free): the walk finds the solution its seed leads to; the others are lost unless
  ``sms_trials`` samples them (``T`` and ``TTT`` chains).
* Both are counted, not fixed: :mod:`harness.reference.losses` traces the light that first
  scatters in the medium through every specular path (:mod:`harness.reference.specular_paths`)
  and sets it against what these connections deliver (:mod:`harness.reference.connection_power`);
  the shortfall is recorded in ``reference.json`` and judged. On a curved, thin medium
  it is large: ``benchmarks/mnee_chains.py --decompose`` (``docs/benchmarks/mnee_chains.md``)
  gives the decomposition per scene and the area-light limit beside it.
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
from harness.reference import mnee_sms as sms  # noqa: E402
from harness.reference.mnee_connect import (  # noqa: E402, F401 (the walk's names, re-exported)
    CROSSING_BINS, MAX_SEGMENT_HITS, MIN_STEP, WALK_FLAGS, ManifoldConnections)
from harness.reference.mnee_vertex import (  # noqa: E402, F401
    MIN_DET, PLANE_SWITCH, POSITION_EPS, generalized_geometry, half_vector_constraint, light_derivative_det,
    plane_refraction_point)

PLUGIN_NAME = "mneevolpath"
DEFAULTS = {"max_depth": -1, "rr_depth": 5, "newton_iterations": 32, "newton_tolerance": 1e-5,
            "ratio_tracking_scale": 2.0, "stats": False, "probe_seeds": 0, "max_crossings": 5, "sms_trials": 0,
            "sms_chains": sms.SMS_CHAINS_DEFAULT, "sms_only": False}
STATS_AOVS = ("mnee_started", "mnee_converged", "mnee_connected",
              "mnee_cross1", "mnee_cross3", "mnee_cross5", "mnee_cross7_more", "mnee_chain_connected", "mnee_lost", "mnee_over_max",
              "mnee_lost_r", "mnee_lost_g", "mnee_lost_b")
SMS_AOVS = ("mnee_sms_found", "mnee_sms_capped")
PROBE_AOVS = ("mnee_probe_rescued", "mnee_probe_missed_r", "mnee_probe_missed_g", "mnee_probe_missed_b")


def _index_spectrum(spec, channel):
    return dr.select(channel == 0, spec[0], dr.select(channel == 1, spec[1], spec[2]))


def _mis(a, b):
    """Power heuristic (exponent 2), 0 where both are 0."""
    a2, b2 = dr.square(a), dr.square(b)
    return dr.select(a2 + b2 > 0, a2 / (a2 + b2), 0.0)


# --------------------------------------------------------------------------- the integrator

class MNEEVolpathIntegrator(ManifoldConnections):
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
        self.sms_trials = int(get("sms_trials"))
        if not 0 <= self.sms_trials <= sms.MAX_TRIALS_LIMIT:
            raise ValueError(f"{PLUGIN_NAME}: sms_trials = {self.sms_trials} must lie in [0, {sms.MAX_TRIALS_LIMIT}]")
        self.sms_chains = sms.parse_chains(str(get("sms_chains")))
        self.sms_only = bool(get("sms_only"))
        if self.sms_only and not self.sms_trials:
            raise ValueError(f"{PLUGIN_NAME}: sms_only = true needs sms_trials > 0 (nothing would be rendered)")
        self._eta_table = None

    def aov_names(self):
        if not self.stats:
            return []
        return (list(STATS_AOVS) + (list(SMS_AOVS) if self.sms_trials else [])
                + (list(PROBE_AOVS) if self.probe_seeds else []))

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

    # ------------------------------------------------------------------ path tracing

    @dr.syntax
    def sample(self, scene, sampler, ray_, medium=None, active=True):
        self._prepare(scene)
        ray = mi.Ray3f(ray_)
        active = mi.Bool(active)
        medium = dr.zeros(mi.MediumPtr) if medium is None else mi.MediumPtr(medium)
        L = mi.Spectrum(0.0)                       # radiance
        rest = 0.0 if self.sms_only else 1.0       # the weight of all light but the sampled solutions
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
            value, direction, nee_pdf, extras, stats = self._connect(
                scene, sampler, mei, medium, nee, depth, lambda w, m: phase.eval_pdf(phase_ctx, mei, w, m)[0])
            # Per-vertex counts; the lost light and the probes' missed light (AOVs *_r, *_g, *_b)
            # carry the throughput.
            for k, name in enumerate(self.aov_names()):
                weight = beta["rgb".index(name[-1])] if name[-2:] in ("_r", "_g", "_b") else 1.0
                counters[k] += dr.select(nee, stats[k] * weight, 0.0)
            phase_val, phase_pdf = phase.eval_pdf(phase_ctx, mei, direction, nee)
            L[nee] += rest * beta * phase_val * value * dr.select(nee_pdf > 0, _mis(nee_pdf, phase_pdf), 1.0)
            weights = [rest] + [1.0] * (len(extras) - 1)           # the chains, then the sampled solutions
            for weight, (extra_value, extra_dir) in zip(weights, extras):   # (distinct paths)
                chained = nee & dr.any(extra_value != 0.0)
                phase_extra, _ = phase.eval_pdf(phase_ctx, mei, extra_dir, chained)
                L[chained] += weight * beta * phase_extra * extra_value

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
            L[hit_emitter] += rest * beta * w_hit * emitter.eval(si, hit_emitter)

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
            L[nee_s] += rest * beta * bsdf_val * em_s * sel_weight * tr_s * w_s

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
