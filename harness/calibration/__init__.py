"""Calibration: fit a mapping family's free parameters to the references, per real-time budget.

``sslpv-harness calibrate`` renders SSLPV over a range of the family's free parameters,
fits them against the references (in-sample, leave one scene out, and each scene alone:
the oracle), and writes a calibrated mapping file (:mod:`sslpv_gl.calibrated`) with a
report page. It sits beside :mod:`harness.regression`, above the runs.

Modules: ``families`` (what can be fitted, with which renderer settings), ``fit`` (the
loss and its minimisation, pure functions), ``scan`` (the GL renders, memoised),
``run`` (the command: scan, fit, validate, compare, write), ``page`` (the report page).
"""
