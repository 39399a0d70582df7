"""Runs: SSLPV configurations rendered, measured against references, and stored.

=====================  ======================================================
module                 job
=====================  ======================================================
:mod:`.params`         parameter grids: command-line lists, expansion, labels
:mod:`.render`         one SSLPV render folder (EXRs, preview, ``render.json``)
:mod:`.worker`         one configuration on a Dask worker: render and measure
:mod:`.sweep`          every configuration of a sweep on Dask, resumable
=====================  ======================================================

Runs sit above the renderers (:mod:`sslpv_gl`, :mod:`harness.reference`), the
metrics and the store, and below the regression machinery and the command line.
"""
