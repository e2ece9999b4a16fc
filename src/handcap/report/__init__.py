"""Reports of solved takes: the layer that combines the stages and their quality figures.

It reads the results of ``solve``, ``objects`` and the readers of ``io`` and
measures them with :mod:`handcap.quality`, so that ``quality`` and ``solve``
need not know each other (``solve`` uses ``quality``'s checks and filters).
"""

from handcap.report.metrics import metrics_table, motion_metrics

__all__ = ["metrics_table", "motion_metrics"]
