"""Ground truth: Mitsuba 3 volumetric path-traced references of the scene suite.

Modules: :mod:`.phase` (the ``gridhg`` phase function), :mod:`.mitsuba_scene`
(scene object -> Mitsuba dict), :mod:`.render` (one reference folder with noise
estimates), :mod:`.cache` (content-addressed cache and the CLI glue),
:mod:`.committed` (the small references committed in ``baselines/refs/``) and
:mod:`.llvm` (finds an LLVM for the ``llvm_*`` variants). Importing
this package does not import Mitsuba; :func:`.mitsuba_scene.use_variant` does.
"""

from harness.reference.cache import default_cache_dir, reference_for, run_reference_cmd
from harness.reference.render import render_reference

__all__ = ["default_cache_dir", "reference_for", "render_reference", "run_reference_cmd"]
