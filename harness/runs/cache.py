"""The result cache: each rendered configuration, stored under a key of everything its render depends on.

A sweep, the nightly job and a study look a configuration up here before they render it,
and a hit is served instead of a render (``--no-cache`` renders everything afresh).
The key (:func:`result_key`) is the sha256 of:

=====================  ==============================================================
part                   what it is
=====================  ==============================================================
``code``               the method's code fingerprint (:mod:`harness.runs.fingerprint`:
                       its modules' syntax trees without docstrings, its shaders
                       without comments): editing one shader re-keys exactly the
                       configurations of the methods that load it
``scene``              the scene's content hash (geometry, camera and image size,
                       lights, boundary, medium grids)
``params``             every parameter of the configuration, and the sha256 of a
                       calibrated mapping file it names
``reference``          the sha256 of the reference's image files and ``reference.json``
``gl_renderer``        the OpenGL renderer string of the machine that renders
``versions``           the versions of the packages that shape an image, and Python's
``format``             :data:`KEY_FORMAT`
=====================  ==============================================================

An entry holds the render (``images.npz``: subsurface, full, mask), what the worker
reported beside it (``result.json``: timings, diagnostics, work counts, warnings ...) and
its metric rows (``metrics.json``), stored under the hash of the code and packages that
computed them (:func:`harness.runs.fingerprint.metrics_fingerprint`). The images and the
reference are in the key, so the rows are served as they are while that hash is the same;
when it is not (a metric's code was edited) they are measured again from the images
(:func:`harness.runs.worker.measure`) and written back: a change of a metric's code needs no
re-render. ``result.json`` records the sha256 of ``images.npz``; an entry whose files are
missing, unreadable, of another key or another :data:`KEY_FORMAT`, or whose images do not
match their hash, is never served: the configuration is rendered again and one line says
why. Entries are written atomically (:func:`harness.io.atomic.atomic_dir`).

The folder (default ``<repo>/cache/results``, ``$SSLPV_RESULT_CACHE``) carries
:data:`CACHE_MARKER`; a non-empty folder without it is not ours and is refused with one
line, before anything is rendered. It can be copied between machines like the reference
cache: the GL renderer string and the package versions are in the key. Its size is kept
under a limit (:data:`DEFAULT_LIMIT_BYTES`; ``$SSLPV_RESULT_CACHE_LIMIT_MB``) by removing the
least recently used entries after each sweep.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from harness import paths
from harness.errors import InputError
from harness.io.atomic import atomic_dir, atomic_write
from harness.runs.fingerprint import method_fingerprint, metrics_fingerprint, package_versions

__all__ = ["KEY_FORMAT", "CACHE_MARKER", "DEFAULT_LIMIT_BYTES", "ResultCache", "SweepCache", "default_cache_dir",
           "result_key", "reference_hash", "STORED", "open_cache", "workers_gl_renderer", "local_gl_renderer"]

#: The key's format: a cache written with another one is not read (one line says so).
KEY_FORMAT = 1
#: In the cache folder: marks it as ours and records the key format.
CACHE_MARKER = ".sslpv-result-cache"
DEFAULT_LIMIT_BYTES = 2 * 1024 ** 3
#: What an entry keeps of a worker's result besides the images and the metric rows.
STORED = ("timings", "gl_renderer", "steps_used", "diagnostics", "calibration", "shared", "work", "precompute",
          "warnings")
_REFERENCE_FILES = ("subsurface.exr", "full.exr", "half_a.exr", "half_b.exr", "mask.exr", "reference.json")


def default_cache_dir():
    env = os.environ.get("SSLPV_RESULT_CACHE")
    return Path(env) if env else paths.REPO / "cache" / "results"


def _limit():
    mb = os.environ.get("SSLPV_RESULT_CACHE_LIMIT_MB")
    if mb is None:
        return DEFAULT_LIMIT_BYTES
    try:
        value = float(mb)
    except ValueError:
        value = -1.0
    if not value > 0:
        raise InputError("SSLPV_RESULT_CACHE_LIMIT_MB", "limit", f"is {mb!r}", "give a size in MB above 0")
    return int(value * 1024 ** 2)


def reference_hash(ref_dir):
    """sha256 over a reference folder's image files and ``reference.json`` (the preview is left out)."""
    h = hashlib.sha256()
    for name in _REFERENCE_FILES:
        p = Path(ref_dir) / name
        if p.is_file():
            h.update(name.encode() + b"\0" + hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def _calibration_sha(params):
    """The sha256 of the calibrated mapping file ``params`` names (its path is validated already), or None."""
    from sslpv_gl.calibrated import load_calibrated, parse_mapping
    from sslpv_gl.material import MAPPINGS

    path = parse_mapping(params.get("mapping"))
    return None if path is None else load_calibrated(path, tuple(MAPPINGS)).sha256


@functools.lru_cache(maxsize=None)
def _code(method):
    """The method's code fingerprint, once per process: hashing its modules costs about 0.1 s, and a
    sweep asks for it once per configuration (the files do not change while a sweep runs)."""
    return method_fingerprint(method)["code"]


def result_key(method, scene_hash, params, ref_hash, gl_renderer):
    """The cache key of one configuration (see the module docstring); ``params`` is its parameter dict."""
    parts = {"format": KEY_FORMAT, "code": _code(method), "method": method,
             "scene": scene_hash, "params": params, "calibration": _calibration_sha(params),
             "reference": ref_hash, "gl_renderer": gl_renderer, "versions": package_versions()}
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()


class ResultCache:
    """One cache folder. :meth:`get` serves an entry or says why not; :meth:`put` stores a worker's result."""

    def __init__(self, root=None, limit_bytes=None, log=None):
        self.root = Path(root) if root is not None else default_cache_dir()
        self.limit = _limit() if limit_bytes is None else int(limit_bytes)
        self.log = log or (lambda line: None)
        self.hits = self.misses = self.rejected = 0
        self._check()

    def _check(self):
        """Refuse a folder that is not ours; start over (one line) when ours has another key format."""
        marker = self.root / CACHE_MARKER
        if self.root.exists() and not self.root.is_dir():
            raise InputError(self.root, "cache", "exists and is not a folder", "remove it, or set SSLPV_RESULT_CACHE")
        if self.root.is_dir() and any(self.root.iterdir()) and not marker.is_file():
            raise InputError(self.root, "cache", "is a non-empty folder that is not a result cache of the harness",
                             "point SSLPV_RESULT_CACHE at an empty or new folder")
        if marker.is_file():
            try:
                fmt = json.loads(marker.read_text()).get("key_format")
            except (OSError, ValueError, AttributeError):
                fmt = None
            if fmt != KEY_FORMAT:
                self.log(f"result cache {self.root}: written with key format {fmt!r}, this harness uses "
                         f"{KEY_FORMAT}; its entries are removed and rendered again")
                for child in self.root.iterdir():
                    if child.is_dir() and len(child.name) == 2:
                        shutil.rmtree(child, ignore_errors=True)
                marker.unlink()

    def _ensure_marker(self):
        marker = self.root / CACHE_MARKER
        if not marker.is_file():
            self.root.mkdir(parents=True, exist_ok=True)
            marker.write_text(json.dumps({"format": "sslpv-result-cache", "key_format": KEY_FORMAT}) + "\n")

    def entry(self, key):
        return self.root / key[:2] / key

    def get(self, key, label=""):
        """The stored result (images, mask and :data:`STORED`) of ``key``, or None (a miss; a bad entry is logged)."""
        folder = self.entry(key)
        if not folder.is_dir():
            self.misses += 1
            return None
        why = None
        try:
            info = json.loads((folder / "result.json").read_text())
            data = (folder / "images.npz").read_bytes()
            if info.get("key") != key or info.get("key_format") != KEY_FORMAT:
                why = f"it was written for key format {info.get('key_format')!r} / another key"
            elif hashlib.sha256(data).hexdigest() != info.get("images_sha256"):
                why = "its images do not match their recorded hash"
            else:
                with np.load(io.BytesIO(data), allow_pickle=False) as z:
                    images = {"subsurface": z["subsurface"], "full": z["full"]}
                    mask = z["mask"]
        except (OSError, ValueError, KeyError, AttributeError) as exc:
            why = f"it cannot be read ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
        if why is not None:
            self.rejected += 1
            self.misses += 1
            self.log(f"result cache: entry {key[:16]}{' (' + label + ')' if label else ''} is not used: {why}; "
                     "rendering it again")
            return None
        os.utime(folder)                                   # least recently used goes first (prune)
        self.hits += 1
        out = {k: info["result"].get(k) for k in STORED}
        out.update(status="ok", images=images, mask=mask, cached=key, metrics=self._metrics(folder, key))
        return out

    def _metrics(self, folder, key):
        """The entry's metric rows if they were computed by today's metric code, else None (measure again)."""
        try:
            m = json.loads((folder / "metrics.json").read_text())
        except (OSError, ValueError):
            return None
        if not isinstance(m, dict) or m.get("key") != key or m.get("metrics_code") != metrics_fingerprint() \
                or not isinstance(m.get("rows"), list):
            return None
        return m["rows"]

    def put_metrics(self, key, rows):
        """Keep ``rows`` (:func:`harness.runs.worker.measure`) beside the entry of ``key``, if it exists."""
        folder = self.entry(key)
        if not folder.is_dir():
            return
        try:
            # No default=: a row that JSON cannot hold exactly is not kept (it is measured next time).
            text = json.dumps({"key": key, "metrics_code": metrics_fingerprint(), "rows": rows}) + "\n"
            with atomic_write(folder / "metrics.json") as tmp:
                tmp.write_text(text)
        except (OSError, TypeError, ValueError, InputError):
            pass                                           # an optimisation: the rows are measured next time

    def put(self, key, result):
        """Store an ``ok`` worker result under ``key`` (images, mask and :data:`STORED`)."""
        if result.get("status") != "ok":
            return
        self._ensure_marker()
        buf = io.BytesIO()
        np.savez_compressed(buf, subsurface=np.asarray(result["images"]["subsurface"], np.float32),
                            full=np.asarray(result["images"]["full"], np.float32),
                            mask=np.asarray(result["mask"], bool))
        data = buf.getvalue()
        info = {"key": key, "key_format": KEY_FORMAT, "images_sha256": hashlib.sha256(data).hexdigest(),
                "written": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "result": {k: result.get(k) for k in STORED}}
        folder = self.entry(key)
        shutil.rmtree(folder, ignore_errors=True)          # a rejected entry of the same key
        with atomic_dir(folder) as tmp:
            (tmp / "images.npz").write_bytes(data)
            (tmp / "result.json").write_text(json.dumps(info, default=str) + "\n")
        if result.get("metrics") is not None:
            self.put_metrics(key, result["metrics"])

    def prune(self):
        """Remove least recently used entries until the folder is under the limit; returns bytes removed."""
        if not self.root.is_dir():
            return 0
        entries = []
        for d in self.root.glob("??/*"):
            if d.is_dir():
                size = sum(f.stat().st_size for f in d.iterdir() if f.is_file())
                entries.append((d.stat().st_mtime, size, d))
        total = sum(e[1] for e in entries)
        removed = 0
        for _, size, d in sorted(entries):
            if total - removed <= self.limit:
                break
            shutil.rmtree(d, ignore_errors=True)
            removed += size
        return removed


# --------------------------------------------------------------------------- a sweep's use of the cache

def local_gl_renderer():
    """The OpenGL renderer string of this machine (what a LocalCluster's workers report)."""
    from sslpv_gl.context import create_context

    ctx = create_context()
    try:
        return str(ctx.info.get("GL_RENDERER", "unknown"))
    finally:
        ctx.release()


def workers_gl_renderer(client):
    """The renderer string of a sweep's workers: this machine's for a LocalCluster (no client yet), else a worker's."""
    if client is None:
        return local_gl_renderer()
    return client.submit(local_gl_renderer, pure=False, key="sslpv-gl-renderer").result()


def open_cache(cache, what="sweep"):
    """``run_sweep``'s (or a calibration's) ``cache`` argument -> a :class:`ResultCache` or None.

    True: the default folder; a :class:`ResultCache`: itself; False or None: no cache. An entry
    that is not served says why on stderr even under ``--no-progress``: a warning, not progress,
    on a line that names ``what`` uses the cache.
    """
    from harness.progress import Progress

    if cache is False or cache is None:
        return None
    if isinstance(cache, ResultCache):
        return cache
    return ResultCache(log=Progress(what, None, enabled=True).log)


class SweepCache:
    """What a sweep needs of the cache: each configuration's key, the hits served, the renders stored.

    ``gl_renderer`` is the renderer string the sweep's workers report; a rendered result that
    reports another one (a worker of a foreign machine) is not stored.
    """

    def __init__(self, cache, gl_renderer, ref_dirs):
        self.cache, self.gl_renderer = cache, gl_renderer
        self._ref_hash = {name: reference_hash(d) for name, d in ref_dirs.items() if d is not None}
        self.keys = {}                                     # store config key -> cache key

    def split(self, todo, method_of):
        """``todo`` -> ``(hits, misses)``; a hit is ``(scene, params, config_key, stored result)``."""
        hits, misses = [], []
        for s, p, key in todo:
            if s.name not in self._ref_hash:                # its reference is rendered in this sweep
                misses.append((s, p, key))
                continue
            method = method_of(p)
            ck = result_key(method, s.content_hash, p.as_dict(), self._ref_hash[s.name], self.gl_renderer)
            self.keys[key] = ck
            res = self.cache.get(ck, label=f"{s.name} {key[:12]}")
            (misses.append((s, p, key)) if res is None else hits.append((s, p, key, res)))
        return hits, misses

    def put(self, config_key, result):
        ck = self.keys.get(config_key)
        if ck is not None and result.get("status") == "ok" and result.get("gl_renderer") == self.gl_renderer:
            self.cache.put(ck, result)
