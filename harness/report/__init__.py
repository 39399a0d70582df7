"""Static HTML report of a results store: per-scene pages with images, error
maps, sortable metric tables and plots; opens from the file system.

>>> from harness.report import build_report
>>> info = build_report("results.sqlite", "reports/latest")   # doctest: +SKIP
>>> info["index"]                                              # doctest: +SKIP
PosixPath('reports/latest/index.html')
"""

from harness.report.build import build_report

__all__ = ["build_report"]
