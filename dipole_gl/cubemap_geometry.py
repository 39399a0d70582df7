"""The cubemap gather's geometry in NumPy, shared by the GL host (:mod:`dipole_gl.cubemap`) and its twin.

The thesis draft (``002_...``, Ch. 4) gathers the directional dipole in three steps: a light
buffer per light, six orthographic cube faces around the object, a combination over the faces.
This module holds what both the GL passes and :mod:`dipole_gl.twin_cubemap` need to agree on:

.. list-table::
   :header-rows: 1

   * - function
     - thesis
     - what
   * - :func:`cube_faces`
     - Ch. 4.1, Step 2 ("the center of the cubemap is placed on the center of the object bounding box")
     - six orthographic cameras: eye, right, up, view direction, world-to-clip matrix, window
       half side, near and far
   * - :func:`disc`
     - Ch. 4.1, Step 2 ("a pre-determined sampling scheme"; Sec. 4.2, which would say which, is empty)
     - ``k`` points of the unit disc, each covering the same area ``pi / k`` (the thesis's
       assumption): the Vogel spiral ``rho_j = sqrt((j + 1/2)/k)``, ``theta_j = j (3 - sqrt 5) pi``
   * - :func:`rotations`
     - Ch. 4.1 ("an algorithm that progressively improves ... while there are no changes")
     - one disc rotation per frame: ``phi_f = 2 pi frac(f (sqrt 5 - 1)/2)`` (golden-ratio sequence,
       well spread for every number of frames)
   * - :func:`offsets`
     - Sec. 4.3 (the three artefact fixes)
     - ``eps_g``, ``eps_c`` and ``eps_b`` in world units from their settings in texels

The three fixes, with the defaults derived here (the thesis gives no values):

* ``eps_g`` (Sec. 4.3.1): ``x'_o = x_o - eps_g (n_o - w_l (w_l . n_o))`` before the lookup in the
  light buffer. A point on the light's silhouette projects onto the edge of the covered texels; with
  nearest-texel lookups the texel that holds its projection has its centre (where the rasteriser
  decided coverage) up to half a diagonal, ``sqrt(2)/2`` texel, away. Moved inwards by that much
  perpendicular to a locally straight silhouette (there ``|n - w (w.n)| = 1``), the texel's centre
  lies inside the covered region. Default ``eps_g = 0.75`` light-buffer texels (``sqrt 2 / 2``
  rounded up), the texel's size taken at ``x_o``'s depth along the light's axis.
* ``eps_c`` (Sec. 4.3.2): ``x' = x - eps_c n`` before the lookup in a cube face; the same argument
  for a face's silhouette (the component of ``n`` across a face's axis): default ``0.75`` cube texels.
* ``eps_b`` (Sec. 4.3.3): a face sees ``x'`` iff ``d(x') < d_face + eps_b``. On a surface whose normal
  makes the angle ``theta`` with the face's axis, ``x'`` lies ``eps_c`` below the surface along the
  normal, i.e. ``eps_c / cos(theta)`` deeper than the surface along the axis; and the stored depth
  belongs to the texel's centre, up to ``sqrt(2)/2`` texel sideways of ``x'``, which is
  ``sqrt(2)/2 t tan(theta)`` of depth. Both grow with ``theta``; every normal is within
  ``theta* = acos(1/sqrt 3) = 54.7`` degrees of some face's axis (``cos = 1/sqrt 3``, ``tan = sqrt 2``),
  so ``eps_b = 0.75 sqrt 3 + 1 = 2.30`` texels lets the best-aligned face see every point of a flat
  facet: default ``2.5`` cube texels (the margin covers interpolated normals that differ from the
  facet's; measured on ``sphere_homogeneous`` at 128 texels per face, a bias of ``1.5`` texels left 6 of 524
  pixels that no face saw, the worst missing by 1.62 texels at ``theta`` = 46 degrees, within the bound).
  Limit: a wall thinner than ``eps_b`` along a face's axis lets that face see through it.

Limits: every light must lie outside the bounding sphere (SSLPV's light frustum,
:func:`sslpv_gl.rsm.light_view`); a texel of the light buffer or of a face is one surface point
(nearest lookups, no filtering).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sslpv_gl.rsm import look_at

__all__ = ["Face", "CubeFaces", "cube_faces", "disc", "rotations", "offsets", "GOLDEN_ANGLE", "FACE_AXES",
           "EPS_G", "EPS_C", "EPS_B"]

#: The Vogel spiral's angle step, ``pi (3 - sqrt 5)`` (as ``cubemap_gather.comp``).
GOLDEN_ANGLE = float(np.pi * (3.0 - np.sqrt(5.0)))
#: Where each face's camera sits, seen from the centre (+x, -x, +y, -y, +z, -z).
FACE_AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
#: Defaults of the three fixes, in texels (light buffer, cube, cube); derived in the module docstring.
EPS_G, EPS_C, EPS_B = 0.75, 0.75, 2.5


@dataclass(frozen=True)
class Face:
    eye: np.ndarray          # (3,) camera position
    right: np.ndarray        # (3,) window's x axis
    up: np.ndarray           # (3,) window's y axis
    dir: np.ndarray          # (3,) view direction (towards the centre)
    view_proj: np.ndarray    # (4, 4) world -> clip (orthographic)


@dataclass(frozen=True)
class CubeFaces:
    centre: np.ndarray       # (3,) the bounding box's centre
    half: float              # half side of each face's window
    near: float
    far: float
    faces: tuple             # six Face

    def texel(self, size):
        """A face texel's side in world units for ``size`` texels per face side."""
        return 2.0 * self.half / size


def _ortho(half, near, far):
    m = np.zeros((4, 4))
    m[0, 0] = m[1, 1] = 1.0 / half
    m[2, 2] = -2.0 / (far - near)
    m[2, 3] = -(far + near) / (far - near)
    m[3, 3] = 1.0
    return m


def cube_faces(vertices, margin=1.02):
    """Six orthographic faces centred on the bounding box of ``vertices`` (thesis Ch. 4.1, Step 2).

    Every face's window is a square of half side ``margin`` times the box's largest half extent,
    so each face sees the whole object; its camera sits ``2 half`` from the centre with
    ``near = half/2`` and ``far = 7 half/2`` (the box lies between ``half`` and ``3 half``).
    """
    v = np.asarray(vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = float(margin * 0.5 * (hi - lo).max())
    near, far = 0.5 * half, 3.5 * half
    proj = _ortho(half, near, far)
    faces = []
    for axis in FACE_AXES:
        eye = centre + 2.0 * half * axis
        up = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.5 else np.array([0.0, 0.0, 1.0])
        view = look_at(eye, centre, up)
        faces.append(Face(eye, view[0, :3].copy(), view[1, :3].copy(), -view[2, :3].copy(), proj @ view))
    return CubeFaces(centre, half, near, far, tuple(faces))


def disc(k):
    """``(k, 2)`` points of the unit disc, each standing for the area ``pi / k``: the Vogel spiral."""
    j = np.arange(int(k), dtype=np.float64)
    rho = np.sqrt((j + 0.5) / k)
    ang = j * GOLDEN_ANGLE
    return np.stack([rho * np.cos(ang), rho * np.sin(ang)], axis=1)


def rotations(frames):
    """The disc's rotation angle of each frame ``0 .. frames - 1``: ``2 pi frac(f (sqrt 5 - 1)/2)``."""
    f = np.arange(int(frames), dtype=np.float64)
    return 2.0 * np.pi * np.mod(f * 0.5 * (np.sqrt(5.0) - 1.0), 1.0)


def offsets(cube, face_size, eps_c, eps_b):
    """``(eps_c, eps_b)`` in world units from cube texels (``eps_g`` stays in light-buffer texels: its world
    size depends on the point's depth along the light, so the gather converts it per point)."""
    t = cube.texel(face_size)
    return eps_c * t, eps_b * t
