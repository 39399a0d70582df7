"""Runs: SSLPV configurations rendered, measured against references, and stored.

=====================  ======================================================
module                 job
=====================  ======================================================
:mod:`.params`         parameter grids: command-line lists, expansion, labels
:mod:`.render`         one SSLPV render folder (EXRs, preview, ``render.json``)
:mod:`.worker`         one configuration on a Dask worker: render and measure
:mod:`.sweep`          every configuration of a sweep on Dask, resumable
:mod:`.plan`           a sweep's configuration, its configurations, step groups
:mod:`.cluster`        the Dask client and its workers
:mod:`.schedule`       step groups and missing references as tasks
:mod:`.record`         each result's render folder and store row
:mod:`.references`     the ``reference`` command; the references a sweep reads
:mod:`.rivals`         the configurations of methods other than SSLPV
:mod:`.cache`          the result cache; :mod:`.fingerprint`: code fingerprints
=====================  ======================================================

Runs sit above the renderers (:mod:`sslpv_gl`, :mod:`harness.reference`), the
metrics and the store, and below the regression machinery and the command line.
"""
