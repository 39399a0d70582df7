"""The planted errors in the calibration that depends on the material (:mod:`sslpv_gl.material_form`, its
version 3 file and its leave-one-scene-out fit, :mod:`harness.calibration.form`), and in the study's
families of calibrations and extensions; the rest are in
:mod:`.catalogue`."""

from .runner import Mutation

FT = "tests/test_calibrated_form.py"
XT = "tests/test_study_extensions.py"

FORM = (
    Mutation("form_loso_leak", "mapping", "harness/calibration/form.py",
             "train = [n for n in names if n != held]", "train = list(names)",
             (f"{FT}::TestFit::test_held_out_scene_never_reaches_its_fold",),
             "leave one scene out: the held-out scene stays in its own fold's regression"),
    Mutation("form_anchor_in_sample", "mapping", "harness/calibration/form.py",
             'pair = (res["sigma_scale"], res["radiance_scale"]) if held is None else',
             'pair = (res["sigma_scale"], res["radiance_scale"]) if True else',
             (f"{FT}::TestFit::test_fold_anchor_is_the_scalar_fit_without_the_scene",),
             "leave one scene out: every fold anchored (Eq. F6) to the scalar pair fitted WITH the held-out scene"),
    Mutation("form_sigma_tr_without_3", "mapping", "sslpv_gl/material_form.py",
             "np.sqrt(np.maximum(3.0 * sigma_a * st_r, 0.0))", "np.sqrt(np.maximum(sigma_a * st_r, 0.0))",
             (f"{FT}::TestCellForm::test_terms_against_numpy",),
             "the form's sigma_tr = sqrt(sigma_a sigma_t') without the 3 (Eq. F2)"),
    Mutation("form_albedo_unreduced", "mapping", "sslpv_gl/material_form.py",
             "sigma_sr = st * a * (1.0 - gg)", "sigma_sr = st * a",
             (f"{FT}::TestCellForm::test_terms_against_numpy",),
             "the form's reduced albedo and sigma_t' with sigma_s in place of sigma_s (1 - g) (Eq. F3)"),
    Mutation("form_radiance_factor_dropped", "mapping", "sslpv_gl/steps.py",
             'out["radiance_scale"] = out["radiance_scale"] * factor', "pass",
             (f"{FT}::TestCellForm::test_renderer_applies_the_form_per_cell",),
             "the renderer shades with the form's constant radiance scale and drops its per-cell factor"),
    Mutation("form_group_ignores_form", "mapping", "sslpv_gl/renderer.py",
             "groups.setdefault((res.family, res.sigma_scale, res.form), [])",
             "groups.setdefault((res.family, res.sigma_scale), [])",
             (f"{FT}::TestCellForm::test_budgets_that_differ_in_their_form_only",),
             "step groups: budgets with one sigma constant but different forms share one propagation"),
    Mutation("form_material_cache_ignores_form", "mapping", "sslpv_gl/renderer.py",
             "params.phase_scaling, params.boundary_reflect, res.form)",
             "params.phase_scaling, params.boundary_reflect)",
             (f"{FT}::TestCellForm::test_budgets_that_differ_in_their_form_only",),
             "the material cache keyed without the form: a budget renders with another budget's per-cell scales"),
    Mutation("form_extent_off_by_one", "mapping", "sslpv_gl/material_form.py",
             "sides.append(int(idx[-1] - idx[0] + 1))", "sides.append(int(idx[-1] - idx[0]))",
             (f"{FT}::TestCellForm::test_extent_is_the_inside_bounding_box",),
             "the object's extent E of Eq. (F4) one cell short"),
    Mutation("study_form_label_dropped", "cli", "harness/study/spec.py",
             "+ (\" form\" if any(b.form is not None for b in cal.budgets) else \"\")", "",
             (f"{FT}::test_study_names_a_form_apart_from_its_scalar_family",),
             "the study labels a per-cell form as its scalar family: the two share one headline column"),
    Mutation("study_extension_in_paper_family", "cli", "harness/study/table.py",
             "return study_label(params.get(\"mapping\")) + family_suffix(params)",
             "return study_label(params.get(\"mapping\"))",
             (f"{XT}::test_family_names_the_extensions",),
             "an SSLPV configuration with an extension (outside = interior) competes in the paper's family"),
    Mutation("study_extension_outcome_inverted", "cli", "harness/study/extensions.py",
             '"tied": "≈", "worse": "better", "better-in-part"', '"tied": "≈", "worse": "worse", "better-in-part"',
             (f"{XT}::test_each_extension_is_judged_against_its_base",),
             "an extension that beats its base beyond noise is reported as worse"),
    Mutation("study_headline_keeps_extensions", "cli", "harness/study/run.py",
             "paper_rows = [r for r in rows if not is_extension(r)]", "paper_rows = rows",
             ("tests/test_study.py::test_headline_table_and_limits",),
             "the headline table takes the extension families as columns beside the published method"),
)
