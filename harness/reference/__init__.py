"""Ground truth: Mitsuba 3 volumetric path-traced references of the scene suite.

Modules: :mod:`.phase` (the ``gridhg`` phase function), :mod:`.mitsuba_scene`
(scene object -> Mitsuba dict), :mod:`.render` (one reference folder with noise
estimates, rendered by the serial executor), :mod:`.jobs` (the per-seed jobs and their
sums), :mod:`.plan` (the plan of rounds: pilot, steps, top-ups), :mod:`.noise` (the noise
figure), :mod:`.distributed` (the same jobs on a Dask cluster), :mod:`.cost` (the cost model
behind ``reference --estimate``), :mod:`.cache` (content-addressed cache),
:mod:`.committed` (the small references committed in ``baselines/refs/``) and
:mod:`.llvm` (finds an LLVM for the ``llvm_*`` variants). Importing
this package does not import Mitsuba; :func:`.mitsuba_scene.use_variant` does.
"""

from harness.reference.cache import default_cache_dir, reference_for
from harness.reference.render import render_reference

__all__ = ["default_cache_dir", "reference_for", "render_reference"]
