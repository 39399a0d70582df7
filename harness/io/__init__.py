"""Plumbing for files: atomic writes (:mod:`.atomic`) and EXR/PNG images (:mod:`.images`).

The bottom layer of the harness: it imports nothing of the harness but
:mod:`harness.errors`.
"""
