"""Which deliberate errors in the method do the accuracy tests catch?

For every case of ``baselines/accuracy_matrix.toml``, renders SSLPV with a sabotaged
material (absorption doubled; Eq. 3's scattering term dropped, sigma_s' = 0) and
reports whether the accuracy check fails. The check is one-sided: a sabotage that
happens to move SSLPV closer to the reference passes, by design.

    .venv/bin/python benchmarks/accuracy_sensitivity.py
"""

import numpy as np

from harness.regression.accuracy import cases, check_case
from sslpv_gl.renderer import SSLPVRenderer

SABOTAGE = {
    "absorption x2": lambda m: dict(m, sigma_lpv=m["sigma_lpv"] * 2),
    "no Eq. 3 scattering": lambda m: dict(m, sigma_s_prime=np.zeros_like(m["sigma_s_prime"])),
}


def main():
    renderer = SSLPVRenderer()
    original = renderer.lpv_material
    caught = {k: 0 for k in SABOTAGE}
    all_cases = cases()
    print(f"{'scene':<20} {'config':<20} " + " ".join(f"{k:<32}" for k in SABOTAGE))
    for scene, params, tol in all_cases:
        cells = []
        for name, change in SABOTAGE.items():
            renderer.lpv_material = lambda s, p, change=change: change(dict(original(s, p)))
            res = check_case(renderer, scene, params, tol, write_artifacts=False)
            renderer.lpv_material = original
            failed = [c[0] for c in res.failed]
            caught[name] += bool(failed)
            cells.append(("caught: " + ",".join(failed)) if failed else "not caught")
        label = f"N{params.N}-K{params.steps}-{params.mapping}"
        print(f"{scene:<20} {label:<20} " + " ".join(f"{c:<32}" for c in cells))
    for name, n in caught.items():
        print(f"{name}: caught in {n} of {len(all_cases)} cases")


if __name__ == "__main__":
    main()
