"""The extensions beside the published method in the study (``harness.study.extensions``), without GL.

Synthetic rows and images (as ``tests/test_study.py``'s FLIP tests): the family names a configuration
with options the paper does not have gets; each extension family judged against its base family by the
headline's paired judgement (an extension that halves the error on one scene is better beyond noise, one
that renders the same image is tied); the budget's rows only; the outside treatment chosen for the
extensions is the one with the lowest pooled median ratio. The end-to-end study
(``tests/test_study.py``) checks that the headline keeps extension families out.
"""

import numpy as np
import pytest

from harness.study.extensions import base_family, default_outside, effects, extension_tags, family_suffix, is_extension
from harness.study.table import family_of

from .test_study import _StubImages


@pytest.mark.parametrize("params, family", [
    ({"mapping": "collision", "outside": "vacuum"}, "collision"),
    ({"mapping": "collision", "outside": "interior"}, "collision + interior"),
    ({"mapping": "diffusion", "boundary_reflect": "rdr", "outside": "interior"}, "diffusion + interior + R_dr"),
    ({"mapping": "literal", "phase_scaling": "delta-eddington"}, "literal + δ-Eddington"),
    ({"mapping": "collision", "eta2": True, "inject_offset": 0.25}, "collision + η² + offset 0.25"),
    ({"mapping": "collision", "eta2": False, "inject_offset": 0.0, "phase_scaling": "none"}, "collision"),
])
def test_family_names_the_extensions(params, family):
    assert family_of("sslpv", params) == family
    assert base_family(family) == params["mapping"]
    assert (family_suffix(params) != "") == bool(extension_tags(params))


def test_rivals_have_no_extension_family():
    assert family_of("dipole", {"gather": "dense", "outside": "interior"}) == "dipole dense"
    assert not is_extension({"method": "dipole", "family": "dipole dense + S1"})
    assert is_extension({"method": "sslpv", "family": "collision + interior"})


def _rows_and_images():
    rng = np.random.default_rng(5)
    y = 0.2 + rng.random((24, 24, 3))
    ref = {"subsurface": y, "se": 0.002 * y, "mask": np.ones((24, 24), bool), "K": 8}
    renders, rows = {}, []

    def add(scene, family, k, scale, n=32):
        name = f"{scene}/{family}/{n}/{k}"
        renders[name] = y * scale
        params = {"mapping": base_family(family)}
        if family != base_family(family):
            params["outside"] = family.split(" + ")[1]
        rows.append({"scene": scene, "method": "sslpv", "family": family_of("sslpv", params), "setting": name,
                     "N": n, "K": str(k), "render_dir": name, "reference_dir": "ref",
                     "subsurface_relmse": float(np.mean((y * scale - y) ** 2 / (y ** 2 + 1e-2))),
                     "subsurface_energy_ratio": scale})

    add("a", "collision", 8, 1.4)
    add("a", "collision", "steady", 1.2)              # the base's best on a
    add("a", "collision + interior", 8, 1.1)           # the extension halves the error: better
    add("a", "collision + interior", 8, 1.0, n=16)     # outside the budget's grid: ignored
    add("b", "collision", 8, 1.3)
    add("b", "collision + interior", 8, 1.3)           # the same image: tied
    add("b", "collision + absorb", 8, 1.6)             # worse
    add("b", "diffusion + absorb", 8, 1.5)             # no base family rendered
    return rows, _StubImages(renders, ref)


def test_each_extension_is_judged_against_its_base():
    rows, images = _rows_and_images()
    budget = {"grid": 32, "steps": [8, 16, "steady"]}
    found = effects(rows, budget, ["relmse", "energy_ratio"], ["relmse", "energy_ratio"], images)
    fams = {f["family"]: f for f in found["families"]}
    assert set(fams) == {"collision + interior", "collision + absorb", "diffusion + absorb"}
    inter = fams["collision + interior"]
    a, b = inter["cells"]["a"], inter["cells"]["b"]
    assert a["outcome"] == "better" and a["base_setting"] == "a/collision/32/steady"
    assert a["setting"] == "a/collision + interior/32/8"          # the N = 16 row does not compete
    assert a["ratio"] == pytest.approx(rows[2]["subsurface_relmse"] / rows[1]["subsurface_relmse"])
    assert b["outcome"] == "≈" and b["ratio"] == pytest.approx(1.0)
    assert (inter["better"], inter["worse"], inter["scenes"]) == (1, 0, 2)
    assert inter["median_ratio"] == pytest.approx(np.median([a["ratio"], 1.0]))
    assert fams["collision + absorb"]["cells"]["b"]["outcome"] == "worse"
    assert fams["diffusion + absorb"]["cells"]["b"]["outcome"] == "no base"
    assert fams["diffusion + absorb"]["median_ratio"] is None
    assert found["comparisons"] == 3


def test_the_outside_treatment_for_the_extensions():
    rows, images = _rows_and_images()
    found = effects(rows, {"grid": 32, "steps": [8, "steady"]}, ["relmse"], ["relmse"], images)
    d = default_outside(found)
    assert d["outside"] == "interior" and set(d["by_mode"]) == {"interior", "absorb"}
    assert d["by_mode"]["absorb"] > 1 > d["by_mode"]["interior"]
    assert default_outside({"families": []}) is None
    worse = {"families": [{"family": "collision + interior", "cells": {"a": {"ratio": 1.3}, "b": {"ratio": 1.1}}}]}
    assert default_outside(worse)["outside"] == "vacuum"          # nothing beats the paper's treatment


def test_the_transport_mapping_is_judged_against_the_paper_collision():
    fam = family_of("sslpv", {"mapping": "transport", "outside": "absorb"})
    assert fam == "transport + absorb" and is_extension({"method": "sslpv", "family": fam})
    assert base_family(fam) == "collision"
    # its rows say nothing about the outside treatment alone, so they do not choose the extensions' one
    found = {"families": [{"family": "transport + absorb", "cells": {"a": {"ratio": 0.1}}},
                          {"family": "collision + interior", "cells": {"a": {"ratio": 0.9}}}]}
    assert default_outside(found)["outside"] == "interior"


def test_a_calibrated_mapping_names_its_settings_by_its_label():
    cal = "calibrated:baselines/calibrated/collision/calibrated.toml"
    assert family_of("sslpv", {"mapping": cal, "outside": "vacuum", "skip": 2}) == "calibrated collision"
    assert family_of("sslpv", {"mapping": cal, "outside": "absorb"}) == "calibrated collision"


def test_the_lattice_speed_limit_of_a_scene():
    """The study's speed decomposition on the homogeneous back-lit sphere: the median over its cells equals the
    value from the scene file's constants, and each transport family's best row within the budget is shown."""
    from harness.study.limits import _speed
    from harness.study.present import limit_lines
    from sslpv_gl.lattice import d_lpv
    from sslpv_gl.material import map_material_full

    rows = [{"scene": "backlit_sphere", "family": "transport + absorb", "N": 32, "K": k, "setting": f"t{k}",
             "subsurface_relmse": v, "subsurface_energy_ratio": 1.0} for k, v in (("32", 0.2), ("steady", 0.03))]
    rows.append(dict(rows[0], K="128", setting="t128", subsurface_relmse=0.01))     # outside the budget
    sp = _speed(rows, "backlit_sphere", "relmse", {"grid": 32, "steps": [8, 16, 32, 64, "steady"]})
    st, al, g, dx = np.array([5.5, 6.0, 6.5]), np.array([0.995, 0.99, 0.98]), 0.3, 1.26 / 32
    m = map_material_full(st, al, g, dx, "collision")
    want = np.median((1.0 / (3.0 * st * (1.0 - al * g) * dx)) / d_lpv((1 - m["sigma_s_prime"]) + m["sigma_s_prime"] * g))
    assert sp["measured"] and sp["ratio"] == pytest.approx(float(want), rel=1e-6)
    assert [t["setting"] for t in sp["transport"]] == ["tsteady"]
    lim = {"subject": "s", "relmse": 0.1, "floor": 0.01, "steps": {"measured": False, "why": "x"},
           "outside": {"measured": False, "why": "x"}, "boundary": {"measured": False, "why": "x"},
           "speed": sp, "mapping": {"measured": False, "why": "x"}}
    line = next(x for x in limit_lines(lim) if x.startswith("Lattice speed"))
    assert "transport + absorb tsteady" in line, line
