"""The physics mutation suite: planted errors that the tests must catch.

``catalogue.py`` lists exact edits (a constant scaled by 1.03, a sign flipped, a channel
swapped, ...) across the GLSL shaders, the Python physics, the Mitsuba scene builder, the
material mappings, the metrics and the scene fields, each with the smallest test selection
that must catch it. ``runner.py`` applies each one to a temporary copy of the repository
(never to the working tree), runs its selection there, and records whether the tests
failed ("killed") or passed ("survived"). ``test_mutations.py`` runs them all in the normal
pytest run (marker ``mutation``: ``pytest -m mutation`` runs them alone) and fails on any
survivor, which is a bug in the tests.

From the command line (prints the kill rate, every survivor, each failure line)::

    python -m tests.mutations                 # all, two at a time
    python -m tests.mutations eq3_g_times_1_03 ssim_exposure_1_03 --jobs 1
    python -m tests.mutations --list
"""
