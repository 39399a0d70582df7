"""Image metrics for comparing SSLPV renders with path-traced references.

Each metric is a pure function ``f(test, ref, mask=None, **params) ->
MetricResult`` on float32 ``(H, W, 3)`` linear HDR RGB images; the registry
:data:`METRICS` names them and :func:`compute` is the validating front door.

=================  ==============================================  ======
name               what                                            ideal
=================  ==============================================  ======
``rmse``           root-mean-square error                          0
``relmse``         relative MSE, eps = 1e-2 (Rousselle 2011)       0
``mae``            mean absolute error                             0
``smape``          symmetric MAPE, 2|x-y|/(|x|+|y|+eps), eps 1e-2  0
``energy_ratio``   sum(test)/sum(ref) per channel                  1
``si_relmse``      relMSE after the best per-channel scale         0
``ssim``           SSIM of Reinhard-tone-mapped images (Wang 2004) 1
``flip``           HDR-FLIP (Andersson et al. 2020, 2021)          0
``ciede2000_mean`` mean CIEDE2000 (Sharma et al. 2005)             0
``ciede2000_p95``  95th percentile of CIEDE2000                    0
=================  ==============================================  ======
"""

from harness.metrics.colour_difference import ciede2000_mean, ciede2000_p95, delta_e_2000_map
from harness.metrics.perceptual import flip, ssim
from harness.metrics.pixel import energy_ratio, mae, relmse, rmse, si_relmse, smape
from harness.metrics.registry import METRICS, compare_images, compute, compute_all, metric_params, noise_floor
from harness.metrics.result import MetricResult

__all__ = [
    "METRICS", "MetricResult", "compute", "compute_all", "compare_images", "noise_floor",
    "metric_params", "rmse", "relmse", "mae", "smape", "energy_ratio", "si_relmse", "ssim",
    "flip", "ciede2000_mean", "ciede2000_p95", "delta_e_2000_map",
]
