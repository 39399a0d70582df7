"""The sweep's configurations of methods other than SSLPV (``harness.methods``: the dipole rivals).

SSLPV configurations keep their step groups (:mod:`harness.runs.sweep`); a configuration of
another method is a :class:`MethodConfig` (its method and validated parameters), rendered
alone by :func:`harness.runs.worker.run_method` and recorded (``harness.runs.record._record``) with
its method, its precomputation and its work counts. A sweep product names its method
(``{"method": "dipole", "gather": ["dense"], ...}``); one without a method is SSLPV's.
"""

from __future__ import annotations

from dataclasses import dataclass

from harness.methods import DEFAULT_METHOD, get_method
from harness.methods.params import expand, product_method

__all__ = ["MethodConfig", "method_of", "expand_product", "check_scenes", "submit", "store_fields"]


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


def store_fields(config):
    """The store row's extra fields of a configuration: its method and stages (none for SSLPV's)."""
    if method_of(config) == DEFAULT_METHOD:
        return {}
    return {"method": config.method, "stages": get_method(config.method).stages}
