"""Per-stage GL timing: a timer query around each stage, with the host clock beside it.

The GL time of a stage is its ``GL_TIME_ELAPSED`` query, except where the query cannot be
trusted, when the host time between two ``glFinish`` calls (which on a GPU also includes the
driver's overhead, and on Mesa llvmpipe *is* the work) is reported instead, with a warning:

* moderngl reads the query as an unsigned 32-bit value: it saturates at 4.29 s, and llvmpipe
  answers 0xFFFFFFFF for a query it could not time;
* llvmpipe's queries do not see compute dispatches on storage buffers (measured here: a
  compute pass of 8 s host time read 1e-6 ms), so a query under half the host time of a
  stage that took over 1 ms is taken to have missed the work.
"""

from __future__ import annotations

import contextlib
import time

__all__ = ["StageTimer", "warm_up_queries"]

_INVALID = 0xFFFFFFFF


def warm_up_queries(ctx):
    """Spend a context's first timer query (llvmpipe answers it with 0xFFFFFFFF) on a 1x1 clear."""
    fbo = ctx.simple_framebuffer((1, 1))
    q = ctx.query(time=True)
    with q:
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
    _ = q.elapsed
    fbo.release()


class StageTimer:
    """``with timer.stage("gather"): ...`` -> ``timer.ms["gather"]`` (GL time, ms)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.ms = {}
        self.warnings = []

    @contextlib.contextmanager
    def stage(self, name):
        self.ctx.finish()
        q = self.ctx.query(time=True)
        t = time.perf_counter_ns()
        with q:
            yield
        self.ctx.finish()
        wall = time.perf_counter_ns() - t
        ns = q.elapsed
        if ns >= _INVALID:
            value = wall / 1e6
            self.warnings.append(f"GL timer query for '{name}' invalid or saturated ({ns} ns); host time "
                                 "between glFinish calls reported instead")
        elif wall > 1e6 and ns < 0.5 * wall:
            value = wall / 1e6
            self.warnings.append(f"GL timer query for '{name}' saw {ns / 1e6:.3g} ms of {wall / 1e6:.3g} ms host "
                                 "time (a driver that does not time compute work); host time reported")
        else:
            value = ns / 1e6
        self.ms[name] = self.ms.get(name, 0.0) + value
