"""Regression machinery: did a change move SSLPV, and for better or worse?

=====================  ======================================================
module                 job
=====================  ======================================================
:mod:`.verdict`        headline metrics, badness, the per-row verdict rule
:mod:`.baselines`      committed accuracy baselines: read, update, regenerate refs
:mod:`.accuracy`       the pytest accuracy cases against the baselines
:mod:`.nightly`        the nightly matrix, its verdict, report and trends
=====================  ======================================================

It sits above the runs (it sweeps) and the report (the nightly builds one), and
below the command line.
"""
