"""Report artefacts kept by what they are made from, so that an unchanged configuration is not drawn twice.

A report draws, per configuration, tone-mapped PNGs and error maps (FLIP's among them), and
per scene a dozen matplotlib plots; for a nightly of hundreds of configurations that is
minutes of work, repeated every night although most inputs have not changed. Each artefact
here is a pure function of its inputs, so it is stored under the sha256 of:

* the inputs themselves (the image files' bytes, the reference's arrays, the plotted
  configurations' parameters, metrics and costs, every setting of the drawing);
* the code that draws them: the syntax trees, without docstrings, of the report's modules
  and of everything they import in this project (:func:`code_hash`, the import graph of
  :func:`harness.io.source.import_closure`), and the matplotlib version.

A hit copies the stored files into the report; a miss draws them and stores a copy. The
memo lives in ``<repo>/cache/report`` (``$SSLPV_REPORT_CACHE``); anything unreadable is simply
drawn again, and the folder may be deleted at any time.
"""

from __future__ import annotations

import functools
import hashlib
import json
import shutil
from pathlib import Path

from harness.errors import InputError
from harness.io.atomic import atomic_dir

__all__ = ["Memo", "code_hash", "configs_digest", "default_memo_dir"]

#: The report's own modules: their code and the project code they import key every artefact.
_ENTRIES = ("harness.report.build", "harness.report.plots", "harness.report.memo")


def default_memo_dir():
    import os

    from harness import paths

    env = os.environ.get("SSLPV_REPORT_CACHE")
    return Path(env) if env else paths.REPO / "cache" / "report"


@functools.lru_cache(maxsize=1)
def code_hash():
    """sha256 over the report's modules and their imports in this project, and matplotlib's version."""
    import importlib.metadata

    from harness.io.source import import_closure, module_path, python_source_hash

    h = hashlib.sha256(importlib.metadata.version("matplotlib").encode())
    for m in import_closure(_ENTRIES):
        h.update(f"{m}:{python_source_hash(module_path(m))}".encode())
    return h.hexdigest()


def configs_digest(configs):
    """sha256 of what a plot reads of configurations: parameters, method, status, metrics, timings and cost."""
    keep = [{k: c.get(k) for k in ("params", "method", "status", "metrics", "timings", "cost_ms", "steps_used")}
            for c in configs]
    return hashlib.sha256(json.dumps(keep, sort_keys=True, default=str).encode()).hexdigest()


class Memo:
    """A folder of artefacts by key. ``Memo(None)`` keeps nothing (every call draws)."""

    def __init__(self, root):
        self.root = Path(root) if root is not None else None
        self.hits = self.misses = 0

    def key(self, *parts):
        h = hashlib.sha256(code_hash().encode())
        for p in parts:
            h.update(b"\0" + (p if isinstance(p, bytes) else json.dumps(p, sort_keys=True, default=str).encode()))
        return h.hexdigest()

    def produce(self, key, paths, draw):
        """Put the files ``paths`` in place: copied from the memo under ``key``, else by ``draw()`` and then kept.

        ``draw()`` must write every path in ``paths`` (a missing one is simply not kept).
        """
        paths = [Path(p) for p in paths]
        # Kept by position, not by name: the names carry a configuration's id, which another run of
        # the same configuration (or another configuration with the same picture) does not share.
        kept = [f"{i}{p.suffix}" for i, p in enumerate(paths)]
        folder = self.root / key[:2] / key if self.root is not None else None
        if folder is not None and all((folder / k).is_file() for k in kept):
            try:
                for p, k in zip(paths, kept):
                    shutil.copyfile(folder / k, p)
                self.hits += 1
                return
            except OSError:
                pass
        self.misses += 1
        draw()
        if folder is None:
            return
        try:
            shutil.rmtree(folder, ignore_errors=True)     # an incomplete entry of the same key
            with atomic_dir(folder) as tmp:
                for p, k in zip(paths, kept):
                    if p.is_file():
                        shutil.copyfile(p, tmp / k)
        except (OSError, InputError):
            pass                                          # the memo is an optimisation: never fail a report
