"""How many loop iterations one shader invocation may run, and the gathers' chunks that respect it.

Mesa's llvmpipe (the software rasteriser that runs the harness without a GPU) ends a shader
invocation's loops after :data:`LLVMPIPE_LOOP_LIMIT` iterations *in total*, counted across
all of the invocation's loops (``LP_MAX_TGSI_LOOP_ITERATIONS`` in gallivm), and reports no
error: the invocation simply continues after the loop with what it has summed so far. A
gather whose loop runs over the whole surface therefore returns a partial sum, silently. On a
GPU the same long invocation meets the driver's watchdog instead (NVIDIA's display watchdog
ends a dispatch that runs for seconds, losing the context). Both are avoided the same way:
no invocation runs more than :data:`ITERATION_BUDGET` iterations; a loop whose trip count
grows with the scene is split into chunks, one dispatch each, whose partial sums accumulate
in a storage buffer.

Cost model (what :func:`dense_chunk` and :func:`vertex_chunk` count, per invocation), with
``c = DIRPOLE_CALL_ITERATIONS`` the loop iterations of one call of ``dirpole_sd``
(``kernels.glsl``: its loop over the three colours, counted at its full trip count although the
compiler may unroll it; llvmpipe was measured to count it once per call):

* dense gather, far field: one iteration per surface sample, plus for the directional dipole
  its light loop and the kernel's calls: ``1`` or ``1 + L (1 + c)`` per sample;
* dense gather, near field (last dispatch only): the standard dipole ``L + N_RAD``, the
  directional dipole ``L (1 + N_RAD (1 + N_PHI (1 + c)))`` (lights x radial nodes x angles);
* vertex gather: one iteration per neighbour, ``1`` or ``1 + L (1 + c)``;
* hierarchical gather (``gather_tree.comp``): one iteration per node visited, and for the
  directional dipole its light loop and the kernel's calls, ``1`` or ``1 + L (1 + c)`` per node.

Loops of a fixed trip count elsewhere (the G-buffer's eight lights, the shadow filter's 3 x 3)
run outside the gathers' invocations. The audit of every loop is in ``docs/dipole_rivals.md``
(``benchmarks/shader_loops.py``).
"""

from __future__ import annotations

__all__ = ["LLVMPIPE_LOOP_LIMIT", "ITERATION_BUDGET", "DIRPOLE_CALL_ITERATIONS", "near_iterations", "far_iterations_per_sample",
           "dense_chunk", "vertex_chunk", "tree_chunk", "atlas_chunk", "chunks"]

#: llvmpipe's total loop iterations per shader invocation (``LP_MAX_TGSI_LOOP_ITERATIONS``).
LLVMPIPE_LOOP_LIMIT = 65_535
#: Loop iterations of one ``dirpole_sd`` call (its three-colour loop in ``kernels.glsl``).
DIRPOLE_CALL_ITERATIONS = 3
#: The most loop iterations one invocation of a gather may run: below llvmpipe's limit with a margin
#: of 5,535, and a bounded amount of work per dispatch for a GPU's watchdog.
ITERATION_BUDGET = 60_000


def near_iterations(kernel, n_lights, n_rad, n_phi):
    """Loop iterations of the dense gather's near field in one invocation (see the module docstring)."""
    if kernel == "dirpole":
        return n_lights * (1 + n_rad * (1 + n_phi * (1 + DIRPOLE_CALL_ITERATIONS)))
    return n_lights + n_rad


def far_iterations_per_sample(kernel, n_lights):
    """Loop iterations per surface sample (dense) or neighbour (vertex): for dirpole its light loop and kernel calls."""
    return 1 + n_lights * (1 + DIRPOLE_CALL_ITERATIONS) if kernel == "dirpole" else 1


def dense_chunk(kernel, n_lights, n_rad, n_phi, budget=ITERATION_BUDGET):
    """Surface samples per dispatch of the dense gather: the far field's share of ``budget`` after the near field."""
    left = budget - near_iterations(kernel, n_lights, n_rad, n_phi)
    size = left // far_iterations_per_sample(kernel, n_lights)
    if size < 1:
        raise ValueError(f"the near field alone needs more than {budget} loop iterations")
    return int(size)


def vertex_chunk(kernel, n_lights, budget=ITERATION_BUDGET):
    """Neighbours per dispatch of the vertex gather."""
    return int(budget // far_iterations_per_sample(kernel, n_lights))


def tree_chunk(kernel, n_lights, budget=ITERATION_BUDGET):
    """Octree nodes per invocation and dispatch of the hierarchical gather's descent."""
    return int(budget // far_iterations_per_sample(kernel, n_lights))


def atlas_chunk(budget=ITERATION_BUDGET):
    """Links per invocation and dispatch of the atlas gather's pass 2 (one iteration each)."""
    return int(budget)


def chunks(count, size):
    """``[(first, end), ...]`` covering ``range(count)`` in pieces of ``size``; one empty piece when ``count`` is 0."""
    if count <= 0:
        return [(0, 0)]
    return [(first, min(first + size, count)) for first in range(0, count, size)]
