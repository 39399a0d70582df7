"""Where the repository's own folders are, found once from this file's place.

Every module that needs the scene suite, the committed baselines or the default
report folders takes the path from here, so that moving a module never changes
which folder it reads.
"""

from pathlib import Path

#: The repository root (the folder holding ``pyproject.toml``).
REPO = Path(__file__).resolve().parent.parent
#: The scene suite, one folder per scene (``reference_scenes/README.md``).
SUITE_DIR = REPO / "reference_scenes"
#: Committed accuracy baselines and their small references.
BASELINE_DIR = REPO / "baselines"
