r"""Every specular path from the point lights into the medium, by type: the light a manifold connection must find.

An independent route to what ``mneevolpath``'s connections (:mod:`harness.reference.mnee`)
deliver and what they leave out: nothing here uses the manifold walk, its Jacobians or its
seeds. Photons leave each point light (intensity ``I``, W/sr) uniformly inside the cone
that holds the object's bounding sphere (weight ``I Omega_cone / N``) and follow the
boundary deterministically: at every hit (Mitsuba's ray cast; the shading normal, as the
``dielectric`` BSDF refracts with it) the photon splits into a reflected part of weight
``F`` and a refracted part of weight ``1 - F`` (unpolarised Fresnel, :func:`fresnel`; total
internal reflection: ``F = 1``), each times :func:`shading_normal_correction` (1 where the
shading normal is the geometric one), down to :data:`WEIGHT_CUT` of the photon's weight and up to
``max_events`` boundary events. Power carries no ``eta^2`` (radiance does; power does not).
The correction makes the photons carry the light of the camera's transport, which the reference
renders: without it the photons through a refraction on a faceted mesh differ from
``mneevolpath``'s connection by this factor, solution by solution; on a slab whose shading normal is
tilted by 25 degrees they carry 9 % more light (``tests/test_specular_paths.py`` and the planted error
``tracer_without_shading_normal_correction``).

Along every segment inside the medium the power that scatters *for the first time* there is
tallied per colour channel,

    P_seg = w * int_0^l sigma_s(s) exp(-int_0^s sigma_t) ds,

by sub-intervals of :data:`SUBSTEPS` equal parts with the grid's nearest voxel (the
reference's ``nearest`` filter) at each sub-interval's midpoint (exact in a homogeneous
medium), and ``w`` leaves the segment multiplied by its transmittance. A segment's type is the
sequence of boundary events since the light (``E`` enter, ``T`` leave, ``R`` reflect inside,
``r`` reflect outside), collected in classes (:func:`path_class`):

* ``direct``: ``E``, one refraction: what the single manifold walk connects;
* ``chain3``, ``chain5``, ...: ``ETE``, ``ETETE``, ...: through another part of the object,
  what the chains of :mod:`harness.reference.mnee_chain` connect (up to ``max_crossings``);
* ``reflection``: any reflection on the way (``ER``, ``rE``, ``ETRE`` ...): what no straight-seeded
  connection of ``mneevolpath`` makes (specular manifold sampling makes the chains it names,
  :mod:`harness.reference.mnee_sms`; ``by_label`` holds each label's power to hold against them).

The share of the first-scattered power in ``reflection`` (:func:`shares`) is the measured
estimate of the light that the reference loses to specular chains with a reflection vertex
(:mod:`harness.reference.losses`). Photons still alive after ``max_events`` are reported as
``truncated``.

Limits: point lights only (the scene's lights); the estimate weighs the medium by where light
first scatters, not by what the camera sees (a share of the light the medium receives, not of
the image); the object must be the scene's one closed mesh; ``WEIGHT_CUT`` drops
branches lighter than that fraction (their power is reported as ``cut``). Each branch travels in
the medium of the geometric normal's side it leaves on and starts off the surface along the
geometric normal, as the renderer's rays do (Mitsuba's ``target_medium``): at a grazing hit on a
faceted mesh the shading normal may bend a refracted photon back to the outside, or a reflected one
through the surface, and the event then counts as what it did (:func:`event_letter`), never as
light scattering in the air (``tests/test_specular_paths.py``, on the scanned bunny). A branch
inside that meets no surface slipped through the mesh; it is dropped and reported as ``leaked``.
"""

import numpy as np

#: Sub-intervals per medium segment for the first-scattering integral.
SUBSTEPS = 48
#: Branches lighter than this fraction of their photon's initial weight are dropped (tallied as ``cut``).
WEIGHT_CUT = 1e-6
#: A boundary event's new ray starts this far off the surface (scene units).
OFFSET = 2e-5


def fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance and the refracted cosine; ``cos_i > 0`` on the outside, ``eta`` inside / out.

    Returns ``(F, cos_t, e)`` with ``e = n_t / n_i`` the relative index the ray meets
    (``eta`` entering, ``1 / eta`` leaving); ``F = 1`` beyond the critical angle.
    """
    e = np.where(cos_i > 0, eta, 1.0 / eta)
    ci = np.abs(cos_i)
    st2 = (1.0 - ci * ci) / (e * e)
    tir = st2 >= 1.0
    ct = np.sqrt(np.clip(1.0 - st2, 0.0, 1.0))
    rs = (ci - e * ct) / (ci + e * ct)
    rp = (e * ci - ct) / (e * ci + ct)
    return np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp)), ct, e


def shading_normal_correction(d_in, d_out, n, ng):
    """The factor that makes a photon's weight follow the camera's transport where the shading normal is not the
    geometric one: ``|d_in . n| |d_out . ng| / (|d_in . ng| |d_out . n|)`` per branch (N,).

    ``d_in`` is the photon's direction of travel into the surface, ``d_out`` its reflected or refracted one, ``n``
    the shading normal that bent it and ``ng`` the geometric normal. A specular event about a shading normal does
    not conserve the throughput that geometric areas and cosines carry (Veach 1997, "Robust Monte Carlo Methods
    for Light Transport Simulation", Sec. 5.3, the adjoint BSDF with shading normals; pbrt's
    ``CorrectShadingNormal`` in importance mode). Mitsuba's path tracer and ``mneevolpath``, which follow paths
    from the camera (radiance), apply no such factor; a photon from the light must, to carry the same light
    (``tests/test_specular_paths.py``: a slab whose shading normal is tilted from its face). It is 1 where
    ``n = ng`` and for a reflection whose two cosines with ``ng`` are equal; 0 where ``d_in`` grazes the geometric
    surface.
    """
    num = np.abs(np.sum(d_in * n, 1)) * np.abs(np.sum(d_out * ng, 1))
    den = np.abs(np.sum(d_in * ng, 1)) * np.abs(np.sum(d_out * n, 1))
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def event_letter(was_inside, now_inside):
    """The letter of a boundary event by the geometric sides before and after it: ``E`` enter, ``T`` leave,
    ``R`` stay inside, ``r`` stay outside (a refraction about a tilted shading normal that does not cross the
    geometric surface is labelled as the reflection it acts as)."""
    return np.where(was_inside, np.where(now_inside, "R", "T"), np.where(now_inside, "E", "r")).astype(object)


def path_class(label):
    """``direct``, ``chain<k>`` or ``reflection`` for an event string (module docstring)."""
    if "R" in label or "r" in label:
        return "reflection"
    return "direct" if label == "E" else f"chain{len(label)}"


class _Caster:
    """Ray casts against the scene's mesh alone (Mitsuba, the variant set by the caller)."""

    def __init__(self, mesh):
        import mitsuba as mi

        from harness.reference.mitsuba_scene import mitsuba_mesh

        self.mi = mi
        self.scene = mi.load_dict({"type": "scene", "o": mitsuba_mesh(mesh)})

    def __call__(self, o, d):
        mi = self.mi
        ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, i].astype(np.float32)) for i in range(3)]),
                       mi.Vector3f(*[mi.Float(d[:, i].astype(np.float32)) for i in range(3)]))
        si = self.scene.ray_intersect(ray)
        valid = np.asarray(si.is_valid())
        t = np.where(valid, np.asarray(si.t, np.float64), np.inf)
        p = np.stack([np.asarray(si.p[i], np.float64) for i in range(3)], 1)
        n = np.stack([np.asarray(si.sh_frame.n[i], np.float64) for i in range(3)], 1)
        ng = np.stack([np.asarray(si.n[i], np.float64) for i in range(3)], 1)
        return valid, t, p, n, ng


def _grid_lookup(medium, x):
    """``(sigma_t, albedo)`` (N, 3) at points ``x`` (N, 3): the nearest voxel (voxel i centred at bmin + (i + 0.5) h)."""
    st, al = np.asarray(medium.sigma_t, np.float64), np.asarray(medium.albedo, np.float64)
    nz, ny, nx, _ = st.shape
    lo, hi = np.asarray(medium.bbox_min, np.float64), np.asarray(medium.bbox_max, np.float64)
    f = (x - lo) / (hi - lo) * np.array([nx, ny, nz])
    i = np.clip(np.floor(f).astype(np.int64), 0, np.array([nx, ny, nz]) - 1)
    return st[i[:, 2], i[:, 1], i[:, 0]], al[i[:, 2], i[:, 1], i[:, 0]]


def substeps(medium, o, d, length):
    """The first-scattering integral's sub-intervals along each segment, one at a time (module docstring): yields
    ``(sigma_t, albedo, tr, tk)`` (each (m, 3)): the nearest voxel's values at the sub-interval's midpoint, the
    transmittance to its start and across it; its first-scattered power per unit weight is ``tr albedo (1 - tk)``."""
    tr = np.ones((len(o), 3))
    h = length / SUBSTEPS
    for k in range(SUBSTEPS):
        st, al = _grid_lookup(medium, o + ((k + 0.5) * h)[:, None] * d)
        tk = np.exp(-st * h[:, None])
        yield st, al, tr, tk
        tr = tr * tk


def _segment(medium, o, d, length):
    """First-scattered power per unit weight along each segment, and its transmittance (module docstring)."""
    dep = np.zeros((len(o), 3))
    for _, al, tr, tk in substeps(medium, o, d, length):
        dep += tr * al * (1.0 - tk)
    return dep, tr * tk


def _cone_directions(apex, center, radius, n, rng):
    """``n`` stratified directions uniform in the cone from ``apex`` around the sphere (center, radius); its solid angle."""
    axis = center - apex
    dist = np.linalg.norm(axis)
    axis /= dist
    cos_max = np.sqrt(max(0.0, 1.0 - (radius / dist) ** 2)) if dist > radius else -1.0
    u = (np.arange(n) + rng.random(n)) / n
    cos_t = 1.0 - u * (1.0 - cos_max)
    phi = 2.0 * np.pi * rng.random(n)
    sin_t = np.sqrt(np.clip(1.0 - cos_t ** 2, 0.0, 1.0))
    a = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    d = cos_t[:, None] * axis + (sin_t * np.cos(phi))[:, None] * e1 + (sin_t * np.sin(phi))[:, None] * e2
    return d, 2.0 * np.pi * (1.0 - cos_max)


def trace(scene, eta=None, photons=1 << 18, max_events=8, seed=0, record=None):
    """First-scattered power (W, per channel) by path type from every point light of ``scene``.

    ``eta`` defaults to the scene's boundary index. Mitsuba's variant must be set
    (:func:`harness.reference.mitsuba_scene.use_variant`). Returns ``{"by_label": {label:
    (3,)}, "by_class": {class: (3,)}, "truncated": (3,), "cut": (3,), "leaked": (3,), "photons": n}``
    (``leaked``: weight of rays that left the object through a grazing hit without a surface, dropped),
    and ``total_se`` (3,): the standard error of the total first-scattered power (each photon's deposits,
    all its branches together, are one sample of its stratum of the cone; collapsed pairs of strata).

    ``record``: a list to which every batch of segments inside the medium is appended, as a dict of ``o``, ``d``,
    ``t`` (start, direction, length), ``w`` (3,) the weight entering the segment, ``label``, ``verts``
    (m, len(label), 3) the boundary events' positions from the light, ``pid`` the photon and ``light`` the
    index of its light in ``scene.lights`` (:mod:`harness.reference.coverage` draws first-scatter points
    from them).
    """
    eta = float(scene.boundary.eta if eta is None else eta)
    cast = _Caster(scene.mesh)
    rng = np.random.default_rng(seed)
    v = np.asarray(scene.mesh.vertices, np.float64)
    center = 0.5 * (v.min(0) + v.max(0))
    radius = float(np.linalg.norm(v - center, axis=1).max()) * 1.001
    by_label, truncated, cut, leaked = {}, np.zeros(3), np.zeros(3), np.zeros(3)
    variance = np.zeros(3)
    for light_index, light in enumerate(scene.lights):
        y = np.asarray(light.position, np.float64)
        d, omega = _cone_directions(y, center, radius, photons, rng)
        o = np.tile(y, (photons, 1))
        w = np.tile(np.asarray(light.intensity, np.float64) * omega / photons, (photons, 1))
        w0 = w.max(1)
        inside = np.zeros(photons, bool)
        labels = np.array([""] * photons, dtype=object)
        pid = np.arange(photons)                 # the photon each branch came from
        hist = None if record is None else np.zeros((photons, 0, 3))   # each branch's boundary events so far
        per_photon = np.zeros((photons, 3))
        for event in range(max_events + 1):
            if len(o) == 0:                      # every branch escaped or was cut (Dr.Jit refuses empty casts)
                break
            valid, t, p, n, ng = cast(o, d)
            # A ray "inside" that meets no surface slipped through the mesh (a crack between triangles, or an
            # offset beyond a thin part): dropped, its weight reported as leaked.
            leaked += w[inside & ~valid].sum(0)
            keep = valid
            o, d, w, w0, inside, labels, t, p, n, ng, pid = (a[keep] for a in (o, d, w, w0, inside, labels, t, p, n, ng,
                                                                             pid))
            if record is not None:
                hist = hist[keep]
            if inside.any():
                if record is not None:
                    record.append({"o": o[inside], "d": d[inside], "t": t[inside], "w": w[inside],
                                   "label": labels[inside], "verts": hist[inside], "pid": pid[inside],
                                   "light": light_index})
                dep, tr = _segment(scene.medium, o[inside], d[inside], t[inside])
                power = w[inside] * dep
                np.add.at(per_photon, pid[inside], power)
                for lab in np.unique(labels[inside]):
                    m = labels[inside] == lab
                    by_label[lab] = by_label.get(lab, np.zeros(3)) + power[m].sum(0)
                w[inside] = w[inside] * tr
            if event == max_events:
                truncated += w.sum(0)
                break
            # ---- split at the boundary: reflected F, refracted 1 - F (shading normal, facing the ray)
            cos_n = np.sum(d * n, 1)
            facing = np.where((cos_n < 0)[:, None], n, -n)
            ci = np.abs(cos_n)
            F, ct, e = fresnel(np.where(inside, -ci, ci), eta)
            refl = d + 2.0 * ci[:, None] * facing
            refr = d / e[:, None] + (ci / e - ct)[:, None] * facing
            refr /= np.linalg.norm(refr, axis=1, keepdims=True)
            wr = w * (F * shading_normal_correction(d, refl, n, ng))[:, None]
            wt = w * ((1.0 - F) * shading_normal_correction(d, refr, n, ng))[:, None]
            mr = wr.max(1) > WEIGHT_CUT * w0
            mt = (F < 1.0) & (wt.max(1) > WEIGHT_CUT * w0)
            cut += wr[~mr].sum(0) + wt[(F < 1.0) & ~mt].sum(0)
            # Each branch is in the medium of the geometric normal's side it leaves on (as Mitsuba's
            # target_medium): a bend about the shading normal that stays on its geometric side stays in its medium.
            in_r, in_t = np.sum(refl * ng, 1) < 0, np.sum(refr * ng, 1) < 0
            o = np.concatenate([p[mr] + OFFSET * np.where(in_r[mr, None], -ng[mr], ng[mr]),
                                p[mt] + OFFSET * np.where(in_t[mt, None], -ng[mt], ng[mt])])
            d = np.concatenate([refl[mr], refr[mt]])
            w = np.concatenate([wr[mr], wt[mt]])
            w0 = np.concatenate([w0[mr], w0[mt]])
            labels = np.concatenate([labels[mr] + event_letter(inside[mr], in_r[mr]),
                                     labels[mt] + event_letter(inside[mt], in_t[mt])])
            inside = np.concatenate([in_r[mr], in_t[mt]])
            pid = np.concatenate([pid[mr], pid[mt]])
            if record is not None:
                hist = np.concatenate([np.concatenate([hist[mr], p[mr, None]], 1),
                                       np.concatenate([hist[mt], p[mt, None]], 1)])
        # The directions are stratified (one per ring of the cone): the variance of the sum by collapsed
        # strata, each pair of neighbouring rings one stratum of two samples (conservative).
        half = photons // 2
        variance += np.square(per_photon[0:2 * half:2] - per_photon[1:2 * half:2]).sum(0)
    by_class = {}
    for lab, val in by_label.items():
        by_class[path_class(lab)] = by_class.get(path_class(lab), np.zeros(3)) + val
    return {"by_label": by_label, "by_class": by_class, "truncated": truncated, "cut": cut, "leaked": leaked,
            "photons": photons, "total_se": np.sqrt(variance)}


def shares(traced, max_crossings):
    """Per channel: the first-scattered power's shares, ``connected`` (direct and chains up to ``max_crossings``),
    ``reflection`` and ``chains_over_max``, as ``{name: (3,)}`` (zeros where nothing scatters)."""
    by = traced["by_class"]
    total = sum(by.values(), np.zeros(3))
    safe = np.where(total > 0, total, 1.0)
    over = sum((v for k, v in by.items() if k.startswith("chain") and int(k[5:]) > max_crossings), np.zeros(3))
    refl = by.get("reflection", np.zeros(3))
    return {"connected": (total - over - refl) / safe, "reflection": refl / safe, "chains_over_max": over / safe,
            "total": total}
