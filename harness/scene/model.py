"""The ``scene.toml`` format as typed models (pydantic v2): one model per table.

``SceneFile.model_validate(data, context={"scene_dir": folder})`` checks every field's
type and range (unknown keys, strings for numbers, NaN and infinities are refused by
:class:`harness.validation.InputModel`), builds the mesh (``[mesh]``,
:mod:`harness.scene.geometry`) and the medium grids (``[medium]``,
:mod:`harness.scene.fields`), and then checks what no single field's type can say:

* the mesh is closed (``[mesh]``'s validator);
* a dielectric boundary's ``eta`` is a supported refractive index (:func:`dielectric_rules`);
* the medium box is a cube larger than zero, and every grid value is in range
  (``[medium]``'s validator, on the evaluated grids);
* the camera's up vector is not parallel to its viewing direction (``[camera]``);
* the box encloses the mesh, and the camera and every light lie outside it (the scene's).

Without ``scene_dir`` in the context only the types are checked (no mesh, no grids).
:func:`json_schema` is the JSON Schema of the format, for editors
(``reference_scenes/scene.schema.json``, ``reference_scenes/README.md``).
"""

from typing import Annotated, Literal, Optional, Union

import numpy as np
from pydantic import Field, PrivateAttr, ValidationInfo, model_validator

from harness.scene.fields import FieldSpec, evaluate_field
from harness.scene.geometry import MeshSpec, points_inside
from harness.validation import FieldProblem, ImageSize, InputModel, NonNegative, Vec3

__all__ = ["SceneFile", "CameraSpec", "LightSpec", "IndexMatchedBoundary", "DielectricBoundary", "BoundarySpec",
           "MediumSpec", "Tolerances", "json_schema", "schema_text", "BOUNDARY_KINDS", "ETA_RANGE",
           "dielectric_rules"]

BOUNDARY_KINDS = ("index-matched", "dielectric")
#: Each grid's allowed range: (low, high, low open, high open).
GRID_RANGES = {"sigma_t": (0.0, np.inf, False, False), "albedo": (0.0, 1.0, False, False),
               "g": (-1.0, 1.0, True, True)}
_GRID_MEANING = {"sigma_t": "extinction, per scene unit, >= 0", "albedo": "single-scattering albedo in [0, 1]",
                 "g": "Henyey-Greenstein g in (-1, 1)"}


def _fmt(v):
    return ", ".join(f"{float(x):g}" for x in v)


class CameraSpec(InputModel):
    """``[camera]``: a pinhole (``docs/conventions.md``, camera convention)."""

    origin: Vec3 = Field(description="eye position", examples=[[0.0, 0.3, 4.2]])
    target: Vec3 = Field(description="point looked at", examples=[[0.0, 0.0, 0.0]])
    up: Vec3 = Field([0.0, 1.0, 0.0], description="up direction (not parallel to target - origin)",
                     examples=[[0.0, 1.0, 0.0]])
    fov_y: Annotated[float, Field(gt=0, lt=180)] = Field(description="full vertical field of view, degrees",
                                                         examples=[34.0])
    width: ImageSize = Field(description="image width, pixels", examples=[128])
    height: ImageSize = Field(description="image height, pixels", examples=[128])

    @model_validator(mode="after")
    def _looks_somewhere(self):
        fwd = np.subtract(self.target, self.origin)
        if np.linalg.norm(fwd) == 0:
            raise FieldProblem("target", f"{_fmt(self.target)} equals origin", "look at a point away from the camera")
        if np.linalg.norm(np.cross(fwd, self.up)) < 1e-9 * np.linalg.norm(fwd) * max(np.linalg.norm(self.up), 1e-300):
            raise FieldProblem("up", f"{_fmt(self.up)} is parallel to the viewing direction (or zero)",
                               "choose an up vector not parallel to target - origin")
        return self


class LightSpec(InputModel):
    """One ``[[lights]]`` entry: a point light."""

    position: Vec3 = Field(description="position, outside the object", examples=[[2.5, 1.8, 2.2]])
    intensity: Annotated[list[NonNegative], Field(min_length=3, max_length=3)] = Field(
        description="RGB radiant intensity, W/sr", examples=[[12.0, 12.0, 12.0]])


class IndexMatchedBoundary(InputModel):
    """The medium's index equals the outside's: no refraction, no reflection (eta 1)."""

    kind: Literal["index-matched"]


#: ``[boundary] max_crossings``: the longest chain of refractions a manifold connection of the exact
#: reference follows (1, 3, 5, ... crossings of the boundary; :mod:`harness.reference.mnee_chain`),
#: its default and its limit (each crossing adds a ray cast per Newton iteration).
MAX_CROSSINGS_DEFAULT = 5
MAX_CROSSINGS_LIMIT = 9

#: ``[boundary] sms_trials`` and ``sms_chains``: specular manifold sampling of the connections a straight
#: seed misses (:mod:`harness.reference.mnee_sms`): the cap on the Bernoulli trials of one solution's
#: weight (0: off), its limit, and the chains sampled by default.
SMS_TRIALS_LIMIT = 4096
SMS_CHAINS_DEFAULT = "T,RT,Tr,TTT"

#: Relative index of refraction (inside / outside) a dielectric boundary may have: above 1
#: (1 is index-matched; a medium less dense than its surroundings is not supported) up to 3.
ETA_RANGE = (1.0, 3.0)


def dielectric_rules(eta, roughness):
    """The rules of a dielectric boundary that no field type states; raises :class:`FieldProblem`.

    ``eta <= 0`` is no refractive index; ``eta = 1`` with ``roughness = 0`` is an
    index-matched boundary; otherwise ``eta`` must lie in :data:`ETA_RANGE`. A smooth
    boundary (``roughness = 0``, rendered exactly by ``harness.reference.mnee``) needs the
    closed two-manifold mesh that ``[mesh]``'s validator asks of every scene.
    """
    if eta <= 0:
        raise FieldProblem("eta", f"eta = {eta:g} is not a refractive index (must be > 0)",
                           "give the medium's index relative to the outside, e.g. 1.4 (skin) or 1.6 (jade)")
    if eta == 1.0 and roughness == 0.0:
        raise FieldProblem("eta", "eta = 1 with roughness = 0 is an index-matched boundary",
                           'use kind = "index-matched"')
    lo, hi = ETA_RANGE
    if not lo < eta <= hi:
        raise FieldProblem("eta", f"eta = {eta:g} is outside the supported range ({lo:g}, {hi:g}]",
                           'use kind = "index-matched" for eta = 1; media less dense than the outside (eta < 1) '
                           "are not supported")


def chains_rule(text):
    """``sms_chains`` names chains of T, R and r that start inside the medium and end outside it."""
    words = [w.strip() for w in str(text).split(",") if w.strip()]
    if not words:
        raise FieldProblem("sms_chains", "names no chain", 'give e.g. "T,RT,Tr,TTT"')
    for word in words:
        inside = True
        for kind in word:
            if kind not in "TRr" or (kind == "R" and not inside) or (kind == "r" and inside):
                raise FieldProblem("sms_chains", f"{word!r}: {kind!r} cannot follow a segment "
                                   f"{'inside' if inside else 'outside'} the medium",
                                   "use T (a refraction), R (a reflection inside) or r (a reflection outside)")
            inside = inside != (kind == "T")
        if inside:
            raise FieldProblem("sms_chains", f"{word!r} ends inside the medium", "end each chain outside, "
                               "toward the light (an odd number of T)")


class DielectricBoundary(InputModel):
    """A dielectric interface of relative index ``eta``: smooth (``roughness = 0``: the exact
    reference, ``mneevolpath``) or rough (GGX alpha > 0: the reference approximates with
    Mitsuba's ``roughdielectric``)."""

    kind: Literal["dielectric"]
    eta: float = Field(description="relative index of refraction (inside / outside), in (1, 3]", examples=[1.4])
    roughness: Annotated[float, Field(ge=0.0, le=1.0)] = Field(
        0.1, description="GGX alpha of the interface; 0 is a smooth interface (exact reference)", examples=[0.0])
    max_crossings: Annotated[int, Field(ge=1, le=MAX_CROSSINGS_LIMIT)] = Field(
        MAX_CROSSINGS_DEFAULT, description="smooth interface: the most boundary crossings a connection from a medium "
        "vertex to a point light follows (1, 3, 5, ...; a light path that leaves the object and passes through "
        f"another part of it crosses 3 times), 1 to {MAX_CROSSINGS_LIMIT}; longer ones are counted and their light "
        "estimated in reference.json", examples=[5])
    sms_trials: Annotated[int, Field(ge=0, le=SMS_TRIALS_LIMIT)] = Field(
        0, description="smooth interface: specular manifold sampling of the connections the straight seed misses "
        "(further solutions of a refraction, chains with a reflection at the boundary): the most Bernoulli trials "
        f"that weigh one solution, 0 (off) to {SMS_TRIALS_LIMIT}; the cap darkens the chains whose solutions few "
        "seeds reach (light reflected off one part of the object into a thin other part, Tr), so raise it until "
        "the exactness verdict stops changing",
        examples=[256])
    sms_chains: str = Field(
        SMS_CHAINS_DEFAULT, description="with sms_trials: the chains sampled, from the medium vertex to the light, "
        "comma-separated: T a refraction, R a reflection inside, r a reflection off the outside (e.g. RT: the light "
        "enters, reflects inside, scatters)", examples=[SMS_CHAINS_DEFAULT])

    @model_validator(mode="after")
    def _supported(self):
        dielectric_rules(self.eta, self.roughness)
        chains_rule(self.sms_chains)
        return self


#: ``[boundary]``; a new kind is one more model in this union (and in :data:`BOUNDARY_KINDS`).
BoundarySpec = Annotated[Union[IndexMatchedBoundary, DielectricBoundary], Field(discriminator="kind")]


class MediumSpec(InputModel):
    """``[medium]``: a world-aligned cubic box with three material grids over it."""

    bbox_min: Vec3 = Field(description="low corner of the grid box", examples=[[-1.05, -1.05, -1.05]])
    bbox_max: Vec3 = Field(description="high corner (a cube that encloses the mesh)", examples=[[1.05, 1.05, 1.05]])
    resolution: Annotated[list[Annotated[int, Field(ge=1, le=512)]], Field(min_length=3, max_length=3)] = Field(
        description="nx, ny, nz of the material grids", examples=[[64, 64, 64]])
    sigma_t: FieldSpec = Field(description=_GRID_MEANING["sigma_t"],
                               examples=[{"kind": "constant", "value": [8.0, 8.0, 8.0]}])
    albedo: FieldSpec = Field(description=_GRID_MEANING["albedo"],
                              examples=[{"kind": "constant", "value": [0.99, 0.99, 0.99]}])
    g: FieldSpec = Field(description=_GRID_MEANING["g"], examples=[{"kind": "constant", "value": [0.0, 0.0, 0.0]}])

    _grids: dict = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _box_and_grids(self, info: ValidationInfo):
        bmin, bmax = np.asarray(self.bbox_min, np.float64), np.asarray(self.bbox_max, np.float64)
        if np.any(bmax <= bmin):
            raise FieldProblem("bbox_max", f"[{_fmt(bmax)}] must be larger than bbox_min [{_fmt(bmin)}] on every "
                               "axis", "swap or widen them")
        extent = bmax - bmin
        if np.ptp(extent) > 1e-9 * extent.max():
            raise FieldProblem("bbox_max", f"box extent {_fmt(extent)} is not a cube; SSLPV's LPV cells are cubes "
                               "over this box", "give the box the same size on every axis")
        scene_dir = (info.context or {}).get("scene_dir")
        if scene_dir is None:
            return self
        grids = {}
        for name in GRID_RANGES:
            grids[name] = evaluate_field(getattr(self, name), tuple(self.resolution), bmin, bmax, name, scene_dir)
            _check_grid(name, grids[name])
        self._grids = grids
        return self

    @property
    def grids(self):
        return self._grids


def _check_grid(name, arr):
    lo, hi, lo_open, hi_open = GRID_RANGES[name]
    bad = ~np.isfinite(arr)
    if bad.any():
        raise FieldProblem(name, f"contains {int(bad.sum())} NaN or Inf values", "fix the grid")
    below = arr <= lo if lo_open else arr < lo
    above = arr >= hi if hi_open else arr > hi
    if below.any() or above.any():
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        worst = float(arr[below | above].flat[0])
        raise FieldProblem(name, f"has {int((below | above).sum())} values outside {lb}{lo}, {hi}{rb} "
                           f"(e.g. {worst:g})", f"keep {name} within {lb}{lo}, {hi}{rb}")


class Tolerances(InputModel):
    """``[tolerances]``: what the references of this scene must reach."""

    reference_rel_se: Optional[Annotated[float, Field(gt=0, lt=1)]] = Field(
        None, description="median relative standard error asked of the reference at the scene size",
        examples=[0.05])
    small_reference_rel_se: Optional[Annotated[float, Field(gt=0, lt=1)]] = Field(
        None, description="... and of the committed 64x64 reference in baselines/refs", examples=[0.03])


class SceneFile(InputModel):
    """A ``scene.toml``: the whole scene, declared once (``reference_scenes/README.md``)."""

    units: Annotated[str, Field(min_length=1)] = Field(description="scene unit; every coefficient is per unit",
                                                       examples=["cm"])
    description: str = Field("", description="one line", examples=["a homogeneous sphere"])
    tags: list[str] = Field([], description="free-form labels", examples=[["homogeneous"]])
    mesh: MeshSpec = Field(description="the object: a closed mesh", examples=[{"kind": "sphere", "radius": 1.0}])
    camera: CameraSpec
    lights: Annotated[list[LightSpec], Field(min_length=1)] = Field(
        description="one or more [[lights]] entries",
        examples=[[{"position": [2.5, 1.8, 2.2], "intensity": [12.0, 12.0, 12.0]}]])
    boundary: BoundarySpec = Field(description="the object's surface", examples=[{"kind": "index-matched"}])
    medium: MediumSpec
    tolerances: Tolerances = Field(default_factory=Tolerances)

    @model_validator(mode="after")
    def _placement(self):
        mesh, medium = self.mesh.mesh, self.medium
        if mesh is None or medium.grids is None:   # types only (no scene folder in the context)
            return self
        bmin, bmax = np.asarray(medium.bbox_min, float), np.asarray(medium.bbox_max, float)
        mlo, mhi = mesh.bbox
        if np.any(mlo < bmin) or np.any(mhi > bmax):
            raise FieldProblem("medium.bbox_min/bbox_max", f"box [{_fmt(bmin)}]..[{_fmt(bmax)}] does not enclose the "
                               f"mesh [{_fmt(mlo)}]..[{_fmt(mhi)}]", "grow the box to enclose the mesh")
        probes = [(("camera", "origin"), self.camera.origin)] + [
            (("lights", i, "position"), lt.position) for i, lt in enumerate(self.lights)]
        inside = points_inside(mesh, np.array([p for _, p in probes], dtype=np.float64))
        for (path, p), flag in zip(probes, inside):
            if flag:
                raise FieldProblem(path, f"{_fmt(p)} lies inside the mesh", "move it outside the object")
        return self


def json_schema():
    """The JSON Schema of ``scene.toml``, with descriptions and examples for editors.

    Written as draft-07 (``definitions``, not ``$defs``): the TOML language servers (taplo,
    behind VS Code's Even Better TOML) read drafts 4 to 7, not the 2020-12 form pydantic
    writes by default. The rules that no schema can state (a closed mesh, a box that encloses
    it, a camera outside the object) are left to the loader.
    """
    schema = SceneFile.model_json_schema(ref_template="#/definitions/{model}")
    schema = {"$schema": "http://json-schema.org/draft-07/schema#", "title": "SSLPV harness scene.toml",
              **{k: v for k, v in schema.items() if k not in ("$defs", "title")},
              "definitions": schema.get("$defs", {})}
    return schema


def schema_text():
    """:func:`json_schema` as the text of ``reference_scenes/scene.schema.json``."""
    import json

    return json.dumps(json_schema(), indent=1, sort_keys=False) + "\n"
