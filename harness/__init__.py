"""Validation harness: measures how far SSLPV (Borlum et al., HPG 2011) is from
physically based ground truth rendered with Mitsuba 3."""

import os as _os

__version__ = "0.1.0"

# OpenMP threads that wait for work sleep instead of spinning. flip_evaluator (FLIP, every
# configuration's metrics, the report's error maps, the verdict's resampled standard errors) runs
# one OpenMP parallel region per exposure; with GNU OpenMP's default (spin) policy its threads
# busy-wait between regions and fight the sweep's other worker and llvmpipe for the cores, which
# makes FLIP many times slower on a loaded machine (benchmarks/bench_openmp_wait.py measures it).
# The values are the same either way; a policy already set in the environment is kept. It must be
# set before the first OpenMP runtime is loaded, hence here, at the top of every harness process.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
