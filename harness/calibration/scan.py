"""GL renders for a calibration: one scene at every budget for one ``sigma_scale``, memoised.

A calibration renders each scene many times: at every sampled ``sigma_scale`` of the scan,
at every budget ``(N, steps)``, then again at each fitted optimum. :class:`Scanner` does it
with the fewest GL calls: for one grid ``N`` the integer step counts come from ONE
:meth:`~sslpv_gl.renderer.SSLPVRenderer.render_steps` propagation (bit-identical to
rendering each count alone), and ``steps = "steady"`` is its own solve. Each result goes
into the :class:`~harness.calibration.fit.SceneSamples` of its (budget, scene), and the
subsurface image itself is kept for the figures that are computed from full images.

With a result cache (:class:`harness.runs.cache.ResultCache`, as
:func:`harness.runs.cache.open_cache` opens it; ``cache/results/`` unless ``$SSLPV_RESULT_CACHE``), each ``(scene, N, steps, sigma_scale)`` image is looked up before it is
rendered and stored after, so a calibration run again, or a form fitted from a calibration's scan
(:mod:`harness.calibration.form`), renders only what no earlier run rendered. Its key is the
result cache's (:func:`harness.runs.cache.result_key`: the method's code, the scene's content hash,
every parameter, the GL renderer string, the package versions) with the parameters marked as a
scan's, so a scan's entry is never served to a sweep (whose entries carry a worker's timings and
diagnostics, which a scan does not keep) nor the reverse. Keying each step count alone is exact
because a grouped propagation is bit-identical to rendering each count alone.

Limits: a render that failed (no steady state, non-finite pixels) is not stored and is tried again;
the cache's own limits hold (an entry that cannot be read or does not match its hash is rendered
again, with one line saying why).
"""

from __future__ import annotations

import time

import numpy as np

from harness.calibration.fit import SceneSamples

__all__ = ["Scanner", "budget_label", "calibration_scanner"]


def budget_label(N, steps):
    return f"N={N} steps={steps}"


def calibration_scanner(cal, settings, cal_path, renderer=None, cache=True, what="calibrate-form"):
    """The :class:`Scanner` of a calibration read back (``cal``, ``settings``: :func:`~harness.calibration.form_files.
    read_sources`), with its scenes and committed references -> ``(scanner, scenes, results cache or None)``.
    A scene whose content changed since the calibration is refused in one line (its oracle no longer holds)."""
    from harness.calibration.run import _reference
    from harness.errors import InputError
    from harness.runs.cache import open_cache
    from harness.runs.references import load_reference
    from sslpv_gl.params import SSLPVParams

    scenes, refs = {}, {}
    for n in cal["scenes"]:
        scene, folder = _reference(n, tuple(cal["sizes"][n]))
        if scene.content_hash != cal["content_hashes"][n]:
            raise InputError(cal_path, f"content_hashes.{n}", "the scene changed since this calibration: its "
                             "oracle no longer holds", f"calibrate the {cal['family']} family again")
        scenes[n], refs[n] = scene, load_reference(folder, (scene.camera.height, scene.camera.width))
    if renderer is None:
        from sslpv_gl.renderer import SSLPVRenderer

        renderer = SSLPVRenderer()
    results_cache = open_cache(cache, what)
    budgets = [(int(N), k) for N, k in cal["budgets"]]
    scanner = Scanner(renderer, scenes, refs, SSLPVParams(mapping=cal["mapping"], **settings), budgets,
                      cache=results_cache)
    return scanner, scenes, results_cache


class Scanner:
    """Renders of ``scenes`` (name -> Scene) against ``refs`` (name -> reference arrays).

    ``base`` is an :class:`~sslpv_gl.params.SSLPVParams` with the family's mapping and
    settings; ``budgets`` a list of ``(N, steps)``. ``progress`` (a
    :class:`harness.progress.Progress`) is advanced once per scene render.
    """

    def __init__(self, renderer, scenes, refs, base, budgets, progress=None, label=None, cache=None):
        self.renderer, self.scenes, self.refs, self.base = renderer, scenes, refs, base
        self.cache = cache                # a ResultCache, or None: render everything
        self.served = 0                   # images served by the cache
        self.label = label or base.mapping              # names the renders in the progress lines
        self.budgets = list(budgets)
        self.progress = progress
        self.samples = {}                 # (budget, scene) -> SceneSamples
        self.images = {}                  # (budget, scene, s) -> full subsurface image (H, W, 3)
        self.failures = []                # (scene, budget, s, error)
        self.renders, self.seconds = 0, 0.0
        for b in self.budgets:
            for name, ref in refs.items():
                m = ref["mask"]
                self.samples[(b, name)] = SceneSamples(name, {k: np.asarray(ref[k], np.float64)[m].ravel()
                                                               for k in ("subsurface", "half_a", "half_b")})
                # SceneSamples names the full reference "full"
                self.samples[(b, name)].refs["full"] = self.samples[(b, name)].refs.pop("subsurface")

    def samples_for(self, budget, names):
        return [self.samples[(budget, n)] for n in names]

    def has(self, budget, name, s):
        return (budget, name, float(s)) in self.images

    def render(self, name, s, budgets=None):
        """Render scene ``name`` at ``sigma_scale = s`` for ``budgets`` (default: all), unless done before."""
        s = float(s)
        want = [b for b in (budgets or self.budgets) if (b, name, s) not in self.images and not self._serve(name, b, s)]
        by_n = {}
        for N, steps in want:
            by_n.setdefault(N, []).append(steps)
        for N, steps_list in by_n.items():
            ints = sorted(k for k in steps_list if not isinstance(k, str))
            modes = [k for k in steps_list if isinstance(k, str)]
            if ints:
                self._run(name, s, N, ints)
            for k in modes:
                self._run(name, s, N, [k])

    def _key(self, name, N, steps, s):
        from harness.runs.cache import result_key

        params = self.base.replace(N=N, steps=steps, sigma_scale=s).as_dict() | {"use": "calibration scan"}
        return result_key("sslpv", self.scenes[name].content_hash, params, None,
                          getattr(self.renderer, "gl_renderer", "unknown"))

    def _keep(self, name, budget, s, img):
        self.images[(budget, name, s)] = img
        self.samples[(budget, name)].add(s, img[self.refs[name]["mask"]].ravel())

    def _serve(self, name, budget, s):
        """Take ``(budget, name, s)`` from the cache -> True, or False (not there, or no cache)."""
        if self.cache is None:
            return False
        got = self.cache.get(self._key(name, *budget, s), label=f"{name} {budget_label(*budget)} sigma_scale={s:.4g}")
        if got is None:
            return False
        self._keep(name, budget, s, np.asarray(got["images"]["subsurface"], dtype=np.float64))
        self.served += 1
        return True

    def image(self, budget, name, s):
        return self.images.get((budget, name, float(s)))

    def _run(self, name, s, N, steps_list):
        scene = self.scenes[name]
        params = self.base.replace(N=N, steps=steps_list[-1], sigma_scale=s)
        t0 = time.perf_counter()
        try:
            if len(steps_list) > 1:
                results = self.renderer.render_steps(scene, params, steps_list)
            else:
                results = [self.renderer.render(scene, params)]
        except (ValueError, FloatingPointError) as exc:   # no steady state at this scale: not a sample
            for k in steps_list:
                self.failures.append((name, (N, k), s, str(exc).splitlines()[0]))
            results = None
        self.seconds += time.perf_counter() - t0
        self.renders += 1
        if self.progress is not None:
            if self.progress.total is not None and self.progress.done >= self.progress.total:
                self.progress.total = self.progress.done + 1            # refinement renders more than planned
            self.progress.advance(detail=f"{self.label}: {name} {budget_label(N, '/'.join(map(str, steps_list)))} "
                                         f"sigma_scale={s:.4g}")
        if results is None:
            return
        for k, res in zip(steps_list, results):
            img = np.asarray(res.subsurface, dtype=np.float64)
            if not np.all(np.isfinite(img)):
                self.failures.append((name, (N, k), s, f"{int(np.count_nonzero(~np.isfinite(img)))} non-finite "
                                      "pixels"))
                continue
            self._keep(name, (N, k), s, img)
            if self.cache is not None:
                self.cache.put(self._key(name, N, k, s), {
                    "status": "ok", "images": {"subsurface": res.subsurface, "full": res.full}, "mask": res.mask,
                    "gl_renderer": res.gl_renderer, "steps_used": res.steps_used, "diagnostics": res.diagnostics,
                    "warnings": list(res.warnings), "timings": res.timings_ms})
