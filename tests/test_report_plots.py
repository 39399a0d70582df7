"""harness.report.plots: series for the refinement plot keep named step modes (steady, auto) as lines."""

from harness.report import plots


def _c(N, steps, v):
    return {"params": {"N": N, "steps": steps, "mapping": "diffusion"},
            "metrics": {"subsurface": {"relmse": {"value": v, "noise_floor": 0.001}}}}


def test_steady_is_a_line_of_its_own_after_the_counts():
    configs = [_c(16, "steady", 0.3), _c(8, "steady", 0.2), _c(8, 32, 0.5), _c(16, 8, 0.6), _c(16, 32, 0.4)]
    series = plots._series(configs, "N", "steps", "subsurface", "relmse")
    assert list(series) == [8.0, 32.0, "steady"]
    assert series["steady"] == [(8.0, 0.2), (16.0, 0.3)]
    assert series[32.0] == [(8.0, 0.5), (16.0, 0.4)]


def test_the_refinement_plot_is_drawn_for_steady_alone(tmp_path):
    configs = [_c(8, "steady", 0.2), _c(16, "steady", 0.3), _c(32, "steady", 0.25)]
    out = tmp_path / "p.png"
    plots.error_vs_param(configs, "subsurface", "relmse", out, "N", "steps")
    assert out.stat().st_size > 1000
