"""GL timing of SSLPV's stages: a timer query and a host clock around each stage.

moderngl reads ``GL_TIME_ELAPSED`` as an unsigned 32-bit value, which saturates at
0xFFFFFFFF ns (4.29 s), and llvmpipe answers that for a query it could not time. Each
stage is therefore also timed on the host between two ``glFinish`` calls
(:func:`stage_timer`), and :func:`_gpu_ms` takes the host time for a saturated query of
a stage longer than 4.29 s.
"""

import contextlib
import time

_QUERY_INVALID = 0xFFFFFFFF      # what llvmpipe returns for an unavailable time query


def _gpu_ms(query_ns, wall_ns, stage, warnings):
    """GL time of one stage in ms.

    moderngl reads GL_TIME_ELAPSED as an unsigned 32-bit value, which saturates at
    0xFFFFFFFF ns (4.29 s; llvmpipe also answers that for a query it could not time).
    A saturated query of a stage whose host time (between two ``finish`` calls)
    exceeds 4.29 s is replaced by that host time, with a warning; otherwise NaN.
    """
    if query_ns < _QUERY_INVALID:
        return query_ns / 1e6
    if wall_ns >= _QUERY_INVALID:
        warnings.append(f"GL timer query for '{stage}' saturated at 4.29 s; the host time between glFinish "
                        "calls is reported instead")
        return wall_ns / 1e6
    warnings.append(f"GL timer query for '{stage}' returned no valid value ({query_ns} ns)")
    return float("nan")


def stage_timer(ctx, queries, stage_wall):
    """``stage(name, query=None)``: a context manager that times one stage with ``query`` (default
    ``queries[name]``) and adds its host nanoseconds to ``stage_wall[name]``."""

    @contextlib.contextmanager
    def stage(name, query=None):
        # A host clock around each stage (after a finish) beside the GL timer query:
        # moderngl reads GL_TIME_ELAPSED as 32 bits, which wraps after 4.29 s.
        ctx.finish()
        t = time.perf_counter_ns()
        with (query if query is not None else queries[name]):
            yield
        ctx.finish()
        stage_wall[name] = stage_wall.get(name, 0) + time.perf_counter_ns() - t

    return stage
