"""Every count that the hand-written documentation states equals the code's.

The README and the hand-written pages of ``docs/`` may say how many scenes the suite has, how
many planted errors the mutation catalogue holds, or how many configurations the standard
matrix runs. Such a number goes stale the day the code changes, so each one is checked here
against the code: the suite folder (:func:`harness.scene.list_scenes`), the catalogue
(``tests/mutations/catalogue.py``) and the matrix (``harness/regression/nightly_matrix.toml``,
expanded as the nightly expands it). Pages that a command writes (a "Written by ..." line in
their first lines, with the command and commit) carry their own provenance and are not read,
nor is the record of measurements (:data:`RECORDS`).
The check is narrow on purpose: the nouns below with a number or a number word right before
them. A hand-written page that needs another count of scenes ("the 3 scenes of this figure")
words it otherwise ("three of the scenes") or has a command write it.
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WORDS = {w: i for i, w in enumerate("zero one two three four five six seven eight nine ten eleven twelve thirteen "
                                    "fourteen fifteen sixteen seventeen eighteen nineteen twenty".split())}
COUNT = re.compile(r"\b(\d[\d,]*|" + "|".join(WORDS) + r")\s+(?:suite\s+|scene-suite\s+)?"
                   r"(scenes|mutations|planted errors|configurations)\b", re.IGNORECASE)


#: A record of measurements, each with the command and the commit that made it: its counts are those of
#: that commit ("the 11 scenes" of a run when the suite had 11), not claims about the code today.
RECORDS = ()


def hand_written_pages():
    pages = [ROOT / "README.md", ROOT / "reference_scenes" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    return [p for p in pages if "Written by" not in "\n".join(p.read_text().splitlines()[:5])
            and str(p.relative_to(ROOT)) not in RECORDS]


def code_counts():
    from harness.regression.nightly import load_matrix
    from harness.runs.sweep import expand_all
    from harness.scene import list_scenes
    from tests.mutations.catalogue import MUTATIONS

    matrix = load_matrix(ROOT / "harness" / "regression" / "nightly_matrix.toml")
    return {"scenes": len(list_scenes()), "mutations": len(MUTATIONS), "planted errors": len(MUTATIONS),
            "configurations": len(matrix["scenes"]) * len(expand_all(matrix["params"]))}


def stated_counts(text):
    """``[(number, noun, context)]`` for every count of the checked nouns in ``text``."""
    out = []
    for m in COUNT.finditer(text):
        n = m.group(1).lower()
        out.append((WORDS[n] if n in WORDS else int(n.replace(",", "")), m.group(2).lower(),
                    text[max(m.start() - 60, 0):m.end() + 20].replace("\n", " ")))
    return out


def wrong_counts(text, counts):
    return [(n, noun, ctx) for n, noun, ctx in stated_counts(text) if n != counts[noun]]


def test_every_stated_count_is_the_codes():
    counts = code_counts()
    wrong = {str(p.relative_to(ROOT)): bad for p in hand_written_pages() if (bad := wrong_counts(p.read_text(), counts))}
    assert not wrong, f"counts that differ from the code's {counts}: {wrong}"


@pytest.mark.parametrize("planted", ["The suite has thirteen scenes.", "the catalogue's 53 mutations",
                                     "its 216 configurations", "The 12 suite scenes"])
def test_a_stale_count_is_caught(planted):
    """Power: a count that is not the code's fails the check."""
    counts = code_counts()
    assert planted.split()[0] and wrong_counts(planted, counts)


def test_the_codes_own_counts_pass():
    counts = code_counts()
    assert not wrong_counts(f"{counts['scenes']} scenes, {counts['mutations']} mutations and "
                            f"{counts['configurations']:,} configurations", counts)
