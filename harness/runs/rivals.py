"""The sweep's configurations of methods other than SSLPV (``harness.methods``: the dipole rivals).

SSLPV configurations keep their step groups (:mod:`harness.runs.sweep`); a configuration of
another method is a :class:`MethodConfig` (its method and validated parameters), rendered
alone by :func:`harness.runs.worker.run_method` and recorded with its method, its
precomputation and its work counts. A sweep product names its method
(``{"method": "dipole", "gather": ["dense"], ...}``); one without a method is SSLPV's.
"""

from __future__ import annotations

from dataclasses import dataclass

from harness.methods import DEFAULT_METHOD, get_method
from harness.methods.params import expand, product_method

__all__ = ["MethodConfig", "method_of", "expand_product", "check_scenes", "submit", "record"]


@dataclass(frozen=True)
class MethodConfig:
    method: str
    params: object                   # the method's validated parameters

    def as_dict(self):
        return get_method(self.method).as_dict(self.params)

    def label(self):
        return get_method(self.method).label(self.params)


def method_of(config):
    """The method of a sweep configuration (SSLPVParams are ``sslpv``'s)."""
    return getattr(config, "method", DEFAULT_METHOD)


def expand_product(product):
    """One sweep product -> its configurations: SSLPVParams for ``sslpv``, else :class:`MethodConfig`."""
    name, lists = product_method(product)
    params = expand(name, lists)
    return params if name == DEFAULT_METHOD else [MethodConfig(name, p) for p in params]


def check_scenes(scenes, configs):
    """Every (scene, method) pair can be rendered, or an InputError (before anything is written)."""
    for name in {method_of(c) for c in configs} - {DEFAULT_METHOD}:
        for s in scenes:
            get_method(name).check_scene(s)


def submit(client, worker_module, scene, size, config, ref_f, floors, priority, attempt=0):
    """Submit one configuration to the cluster -> its future (``attempt``: a resubmission after lost workers)."""
    key = f"{config.method}-{config.label()}-{scene.name}-{scene.content_hash[:8]}" + (f"-r{attempt}" if attempt else "")
    return client.submit(worker_module.run_method, str(scene.path), size, config.method, config.as_dict(), ref_f,
                         floors, key=key, pure=False, retries=2, priority=priority)


def record(store, run_id, scene, config, key, res, out, refs, summary, exposure, write_render):
    """Write one configuration's render folder, then its store row (method, precomputation, work)."""
    render_dir = None
    if res["status"] == "ok":
        summary["gl_renderer"] = summary["gl_renderer"] or res["gl_renderer"]
        render_dir = out / "renders" / scene.name / key[:16]
        res.update(params=dict(config.as_dict(), method=config.method), scene=scene.name,
                   scene_hash=scene.content_hash, exposure=exposure)
        write_render(render_dir, res)
        summary["ok"] += 1
    else:
        summary["failed"] += 1
        summary.setdefault("first_error", f"{scene.name} {config.label()}: {res.get('error')}")
    store.record_config(run_id, scene.name, scene.content_hash, config.as_dict(), res["status"],
                        error=res.get("error"), metrics=res.get("metrics", []), timings=res.get("timings", {}),
                        render_dir=str(render_dir) if render_dir else None, reference_dir=str(refs[scene.name]),
                        diagnostics=res.get("diagnostics"), method=config.method,
                        precompute=res.get("precompute"), work=res.get("work"),
                        stages=get_method(config.method).stages)
