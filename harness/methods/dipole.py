"""The dipole rivals as methods: ``dipole`` (Jensen et al. 2001) and ``dirpole`` (Frisvad et al. 2014).

Both render with :class:`dipole_gl.renderer.DipoleRenderer`; their parameters are
:class:`dipole_gl.params.DipoleParams` (``--gather dense|vertex|cubemap|hierarchical|atlas``, ``--spacing`` for dense and
hierarchical, ``--range`` and ``--density`` for vertex, ``--epsilon`` for hierarchical, ``--cube-size``,
``--light-size``, ``--samples``, ``--frames``, ``--disc-radius``, ``--eps-g``, ``--eps-c`` and ``--eps-b`` for cubemap
(the thesis draft's gather), ``--atlas-size``, ``--links``, ``--link-level`` and ``--adaptive`` for atlas (Carr, Hall
& Hart 2003: ``--link-level`` the non-adaptive scheme, otherwise the adaptive one), ``--shadow-size``, ``--fit refuse|coarsen``: a setting over the gather's budget refused
or coarsened just enough, :mod:`dipole_gl.sizing`; ``--terms both|diffusion|single``: Jensen et al. 2001's complete
BSSRDF, the diffusion kernel alone or single scattering alone, :mod:`dipole_gl.single`). A scene with a non-scattering
voxel inside the mesh (albedo 0) is refused with one line (:mod:`dipole_gl.medium`).
"""

from __future__ import annotations

from harness.errors import InputError

from .base import Method, MethodResult

__all__ = ["DipoleMethod", "CLI_TO_FIELD"]

#: command-line name -> DipoleParams field (shared by both kernels)
CLI_TO_FIELD = {"gather": "gather", "spacing": "spacing", "range": "range", "density": "density",
                "shadow_size": "shadow_size", "fit": "fit", "terms": "terms", "epsilon": "epsilon"}
#: the cubemap gather's (the thesis draft's real-time directional dipole, :mod:`dipole_gl.cubemap`)
CLI_TO_FIELD.update({name: name for name in ("cube_size", "light_size", "samples", "frames", "disc_radius", "eps_g",
                                              "eps_c", "eps_b")})
#: the atlas gather's (Carr, Hall & Hart 2003, :mod:`dipole_gl.atlas_gather`)
CLI_TO_FIELD.update({name: name for name in ("atlas_size", "links", "link_level", "adaptive")})

_TITLES = {"dipole": "standard dipole (Jensen et al. 2001; per-vertex gather: Hao & Varshney 2004) in GLSL",
           "dirpole": "directional dipole (Frisvad, Hachisuka & Kjeldsen 2014) in GLSL"}


class DipoleMethod(Method):
    cli = CLI_TO_FIELD
    stages = ("shadow", "gbuffer", "irradiance", "aggregate", "mipmap", "lightbuffer", "cubemap", "gather", "shading",
              "combine", "single")                                       # the union of the gathers'

    def __init__(self, kernel, shared):
        from dipole_gl.params import DipoleParams
        from dipole_gl.renderer import WORK_UNITS

        self.name = kernel
        self.title = _TITLES[kernel]
        self.params_type = DipoleParams
        self.work_units = WORK_UNITS
        self.precompute_steps = ("material", "sampling", "octree", "atlas", "links", "remesh", "neighbourhoods",
                                 "display")
        self._shared = shared                          # one renderer (one GL context) for both kernels

    def label(self, params):
        d = params if isinstance(params, dict) else params.as_dict()
        return self.name + "-" + "-".join(f"{self.field_to_cli(k)}={v}" for k, v in sorted(d.items())
                                          if k not in ("method",))

    def split_products(self, lists):
        """One product per gather, each with the parameters that belong to it (``--spacing`` to dense,
        ``--range`` and ``--density`` to vertex); one that belongs to no listed gather is refused."""
        from dipole_gl.params import GATHER_FIELDS

        gathers = lists.get("gather", ["dense"])
        out = []
        for g in gathers:
            if g not in GATHER_FIELDS:
                self.make_params(gather=g)                 # the one-line error of an unknown gather
        for name in (n for names in GATHER_FIELDS.values() for n in names):
            if name in lists and not any(name in GATHER_FIELDS[g] for g in gathers):
                owner = next(g for g, names in GATHER_FIELDS.items() if name in names)
                raise InputError("--" + name, name, f"belongs to gather={owner}, which is not among --gather "
                                 f"{','.join(gathers)}", f"drop --{name} or add {owner} to --gather")
        for g in gathers:
            prod = {k: v for k, v in lists.items() if k != "gather" and
                    (k not in (n for names in GATHER_FIELDS.values() for n in names) or k in GATHER_FIELDS[g])}
            out.append({"gather": [g], **prod})
        return out

    def check_scene(self, scene):
        from dipole_gl.medium import scene_material
        from dipole_gl.renderer import MAX_LIGHTS

        if len(scene.lights) > MAX_LIGHTS:
            raise InputError(scene.path, "lights", f"{len(scene.lights)} point lights, method {self.name} supports "
                             f"at most {MAX_LIGHTS}", "remove lights")
        scene_material(scene, self.name)

    def renderer(self):
        if self._shared.get("renderer") is None:
            from dipole_gl.renderer import DipoleRenderer

            self._shared["renderer"] = DipoleRenderer()
        return self._shared["renderer"]

    def release(self):
        r = self._shared.pop("renderer", None)
        if r is not None:
            r.release()

    def render(self, scene, params, renderer=None):
        res = (renderer or self.renderer()).render(scene, self.name, params)
        return MethodResult(full=res.full, subsurface=res.subsurface, mask=res.mask, timings_ms=dict(res.timings_ms),
                            precompute_ms=dict(res.precompute_ms), work=dict(res.work),
                            precompute_work=dict(res.precompute_work), device=res.gl_renderer,
                            warnings=list(res.warnings), info=dict(res.info))
