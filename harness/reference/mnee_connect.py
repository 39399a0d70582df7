"""The connections of ``mneevolpath`` from a medium vertex to the lights: transmittance, walks, chains, probes.

The methods of :class:`ManifoldConnections`, a base of
:class:`harness.reference.mnee.MNEEVolpathIntegrator` (whose docstring states the method, its
parameters and its limits): ratio-tracked transmittance, the single-refraction Newton walk
(:mod:`harness.reference.mnee_vertex`), the chains through 3, 5, ... crossings
(:mod:`harness.reference.mnee_chain`), the straight seed that counts crossings and estimates the
light of the connections not made, and the probe seeds.
"""

from harness.reference.llvm import ensure_libllvm

try:  # must precede ``import mitsuba`` (as in harness.reference.mnee)
    ensure_libllvm()
except RuntimeError:
    pass

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from harness.reference import mnee_chain as chain  # noqa: E402
from harness.reference import mnee_sms as sms  # noqa: E402
from harness.reference.mnee_vertex import (  # noqa: E402
    MIN_DET, PLANE_SWITCH, POSITION_EPS, generalized_geometry, half_vector_constraint, plane_refraction_point)

MIN_STEP = 1e-4            # smallest Newton step factor beta before a walk is given up
#: Bins of :data:`STATS_AOVS`' crossing counts: 1, 3, 5 and 7 or more crossings of the seed segment.
CROSSING_BINS = (1, 3, 5, 7)


class _Vertex:
    """The surface data one manifold walk carries: position, normals and their partials, shape id."""

    FIELDS = ("p", "n", "ng", "dp_du", "dp_dv", "dn_du", "dn_dv")

    @staticmethod
    def of(si):
        return (mi.Point3f(si.p), mi.Vector3f(si.sh_frame.n), mi.Vector3f(si.n), mi.Vector3f(si.dp_du),
                mi.Vector3f(si.dp_dv), mi.Vector3f(si.dn_du), mi.Vector3f(si.dn_dv))


WALK_FLAGS = chain.WALK_FLAGS
MAX_SEGMENT_HITS = 64      # the straight seed segment is followed through at most this many surfaces


class ManifoldConnections(mi.SamplingIntegrator):
    """Next-event estimation from medium vertices through smooth dielectrics (module docstring); an integrator base.

    Expects of its subclass: ``max_depth``, ``max_crossings``, ``newton_iterations``,
    ``newton_tolerance``, ``ratio_tracking_scale``, ``stats``, ``probe_seeds`` and ``_shape_eta``.
    """

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

    def _light_from(self, scene, emitter, u2, last, y, conn):
        """The chain's last segment, from its last vertex ``last`` to the light at ``y``: unoccluded (the other
        air segments are the walk's casts), and the light's intensity toward it. Returns ``(conn, intensity)``."""
        it = dr.zeros(mi.Interaction3f)
        it.p, it.n, it.t = last[0], last[2], 0.0
        conn = conn & ~scene.ray_test(it.spawn_ray_to(y), conn)
        ds1, em1 = emitter.sample_direction(it, u2, conn)
        return conn, em1 * dr.square(ds1.dist)       # point/spot value is I(w) / r^2 (pdf 1)

    def _chain_transmittance(self, medium, x0, verts, kinds, sampler, conn):
        """Ratio-tracked transmittance along a chain's segments inside the medium: ``x0 -> x1`` and each segment
        into a vertex that the light reaches from inside (:func:`harness.reference.mnee_chain.sides`; for
        refractions only, inside the other parts: entry ``i`` -> exit ``i + 1``)."""
        tr = self._ratio_track(medium, x0, verts[0][0], sampler, conn)
        for i, inside in enumerate(chain.sides(kinds)[1:], start=1):
            if inside:
                tr *= self._ratio_track(medium, verts[i - 1][0], verts[i][0], sampler, conn)
        return tr

    def _chain_value(self, scene, sampler, x0, y, direction, eta, shape_id, k, emitter, u2, sel_weight, medium,
                     active):
        """A k-vertex chain (:mod:`harness.reference.mnee_chain`) from the straight seed, and its light at ``x0``.

        Returns ``(connected, value, direction, x1)``: ``value = I G prod(1 - F_i) prod Tr_j /
        p_select`` (``mnee_chain`` docstring) along ``direction`` from ``x0``, ``x1`` its first vertex.
        """
        verts, dist, ok = chain.seed_chain(scene, x0, direction, k, shape_id, active)
        conv, verts, omega, dist = chain.walk_chain(scene, x0, y, verts, direction, dist, eta, shape_id,
                                                    self.newton_iterations, self.newton_tolerance, ok)
        g, _, aux = chain.chain_geometry(omega, dist, verts, y, eta)
        conn, intensity = self._light_from(scene, emitter, u2, verts[-1], y, conv & (g > 0))
        tr = self._chain_transmittance(medium, x0, verts, chain.alternating(k), sampler, conn)
        fresnel_t = chain.chain_fresnel(verts, aux, eta)
        value = dr.select(conn, sel_weight * intensity * fresnel_t * g * tr, 0.0)
        return conn, value, omega, verts[0][0]

    def _seeded(self, scene, sampler, mei, medium, active, depth, emitter, u2, sel_weight):
        """The connections from medium vertex ``mei`` to ``emitter`` that the straight seed leads to.

        The straight seed toward the light, the single refraction's walk from where it leaves the object (or a
        straight, ratio-tracked connection where no dielectric is in the way), and the chains through 3, 5, ...
        crossings where the seed segment crosses that many times (up to ``max_crossings``). Returns a dict:
        ``value``, ``direction``, ``pdf`` of the single or straight connection; ``chain_value``, ``chain_dir``,
        ``chain_conn`` of the chains; ``connected``: ``{k: (x1, converged_or_connected, connected)}`` per number of
        refractions, the first vertex of the solution each straight-seeded walk found (the single walk's
        ``converged`` beside its ``connected``, as specular manifold sampling excludes a converged solution); and
        ``manifold``, ``crossings``, ``same``, ``tr_straight``, ``converged``, ``y``, ``eta``, ``shape_id``,
        ``ds``, ``em_val`` for :meth:`_connect` (:mod:`harness.reference.coverage` reads ``connected``).
        """
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
        # Without chains and statistics nothing needs the crossings: the seed segment is not followed.
        follow = manifold if (self.max_crossings > 1 or self.stats) else mi.Bool(False)
        crossings, same, tr_straight = self._straight_through(scene, sampler, mei, y, medium, shape_id, self.stats,
                                                              follow)
        chain_value = mi.Spectrum(0.0)
        chain_dir = mi.Vector3f(ds.d)
        chain_conn = mi.Bool(False)
        connected = {1: (x1, converged, conn)}    # the solutions already connected, by number of refractions
        for k in range(3, self.max_crossings + 1, 2):
            lane = manifold & same & (crossings == k) & (depth + k < self.max_depth)
            conn_k, value_k, omega_k, x1_k = self._chain_value(scene, sampler, mei.p, y, ds.d, eta, shape_id, k,
                                                               emitter, u2, sel_weight, medium, lane)
            connected[k] = (x1_k, conn_k, conn_k)
            chain_value[conn_k] = value_k
            chain_dir[conn_k] = omega_k
            chain_conn |= conn_k
        return {"value": value, "direction": direction, "pdf": pdf, "chain_value": chain_value, "chain_dir": chain_dir,
                "chain_conn": chain_conn, "connected": connected, "manifold": manifold, "crossings": crossings,
                "same": same, "tr_straight": tr_straight, "converged": converged, "conn": conn, "y": y, "eta": eta,
                "shape_id": shape_id, "ds": ds, "em_val": em_val}

    def _connect(self, scene, sampler, mei, medium, active, depth, phase_value):
        """Next-event estimation from medium vertex ``mei``: manifold connection or a straight one.

        A connection through k crossings adds k + 1 segments to the path's ``depth``; where
        they do not fit into ``max_depth``, an eligible vertex gets no connection of that
        length (a straight one would be blocked by the interface). ``phase_value(direction)`` is
        the phase function toward a direction (used by the probe seeds). Returns
        ``(value, direction, pdf, extras, stats)``: the light arriving at ``mei`` along
        ``direction`` divided by its sampling density (times the phase function gives the
        contribution), the solid-angle pdf used for MIS (0 for delta lights), ``extras``: a list
        of further ``(value, direction)`` pairs, each a distinct path added to the first (the
        chain through 3, 5, ... crossings found where the seed segment crosses that many times,
        up to ``max_crossings``; with ``sms_trials``, the specular manifold sampling estimates of
        :mod:`harness.reference.mnee_sms`), and the :data:`STATS_AOVS` of this vertex (counts,
        then the lost light times the phase function).
        """
        idx, sel_weight, _ = scene.sample_emitter(sampler.next_1d(active), active)
        emitter = dr.gather(mi.EmitterPtr, scene.emitters_dr(), idx, active)
        u2 = sampler.next_2d(active)
        s = self._seeded(scene, sampler, mei, medium, active, depth, emitter, u2, sel_weight)
        manifold, y, eta, shape_id, ds, em_val = s["manifold"], s["y"], s["eta"], s["shape_id"], s["ds"], s["em_val"]
        value, direction, pdf, conn, converged = s["value"], s["direction"], s["pdf"], s["conn"], s["converged"]
        crossings, chain_conn, tr_straight = s["crossings"], s["chain_conn"], s["tr_straight"]
        connected = {k: v[:2] for k, v in s["connected"].items()}
        x1 = connected[1][0]
        extras = [(s["chain_value"], s["chain_dir"])]
        # ---- specular manifold sampling: further refraction solutions and chains with a reflection
        sms_found, sms_capped = mi.Bool(False), mi.Bool(False)
        if self.sms_trials:
            for kinds in self.sms_chains:
                lane = manifold & (depth + len(kinds) < self.max_depth)
                exclude = connected.get(len(kinds)) if set(kinds) == {"T"} else None
                v, d, found, capped = sms.sampled_value(self, scene, sampler, mei.p, y, kinds, eta, shape_id, emitter,
                                                        u2, sel_weight, medium, self.sms_trials, lane, exclude)
                extras.append((v, d))
                sms_found |= found
                sms_capped |= capped
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
            if self.sms_trials:
                stats += [dr.select(sms_found, 1.0, 0.0), dr.select(sms_capped, 1.0, 0.0)]
        if self.probe_seeds:
            stats += self._probe(scene, sampler, mei.p, y, ds.d, eta, emitter, u2, sel_weight, medium, manifold,
                                 conn, x1, phase_value)
        return value, direction, pdf, extras, stats

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
