"""The single-scattering stage of a rival's frame: Jensen et al. 2001's S^(1) (:mod:`dipole_gl.single`) on a
gather's G-buffer, checked against its NumPy twin (:func:`dipole_gl.check.check_single`) every render.

``r`` is the :class:`dipole_gl.renderer.DipoleRenderer` whose programs, targets and material cache the stage
uses; it keeps the read-backs of the last pass in ``r._last_single`` (the twin tests read them).

Limits: those of :mod:`dipole_gl.single` (a straight refracted view ray; the light's attenuation along a
straight line to each march point).
"""

from . import check, gbuffer, single


def run(r, scene, params, medium, views, timer, work, info, gb, out_sub, out_full, add):
    """The ``single`` stage (:mod:`dipole_gl.single`) on the G-buffer ``gb``, checked against its twin
    (``info["single"]``) -> S^(1) (H, W, 3) as read back."""
    cam = scene.camera
    W, H, s = cam.width, cam.height, params.shadow_size
    with timer.stage("single"):
        rsm_prog = r._program(("rsm",))
        atlas = single.render_light_atlas(r.ctx, rsm_prog, r._mesh_vao(scene, rsm_prog, "rsm"), r._targets, scene,
                                          s, views)
        s1_tex = r._targets.get("dipole_single", (W, H), 1).textures[0]
        single.run(r._program(("single",)), gb, atlas, medium, out_sub, out_full, s1_tex, scene, views, s, add)
    s1 = gbuffer.read(s1_tex, W, H)
    covered = s1[..., 3] > 0.5
    work["single"] = int(covered.sum()) * single.N_MARCH * len(scene.lights)
    gview = {"position": gbuffer.read(gb.textures[0], W, H)[..., :3],
             "normal": gbuffer.read(gb.textures[1], W, H)[..., :3], "mask": covered}
    atlas_host = single.read_atlas(atlas)
    info["single"] = check.check_single(scene, r._material(scene, info["kernel"])[0].value, views, s,
                                        atlas_host, gview, s1[..., :3])
    r._last_single = {"atlas": atlas_host, "views": views, "position": gview["position"],
                      "normal": gview["normal"], "mask": covered, "single": s1[..., :3]}
    return s1[..., :3]


def added(r, out_name, scene, params, medium, views, timer, work, info, dbg):
    """S^(1) on the gather's G-buffer (``dipole_gbuffer``) added to its output target ``out_name``, whose
    diffusion term the gather has checked already -> (subsurface, full) (H, W, 4) as read back."""
    W, H = scene.camera.width, scene.camera.height
    gb = r._targets.get("dipole_gbuffer", (W, H), 5)
    out = r._targets.get(out_name, (W, H), 2)
    run(r, scene, params, medium, views, timer, work, info, gb, out.textures[0], out.textures[1], add=True)
    if dbg is not None:
        dbg["single_pass"] = r._last_single
    return gbuffer.read(out.textures[0], W, H), gbuffer.read(out.textures[1], W, H)
