"""The suite's modes: every visibility mode the style knows, the paper's methods first."""

from __future__ import annotations

from camdirector.evaluation.toric.suite import MODE_LABELS, MODES
from camdirector.pipeline.style import VisibilityMode


def test_the_suite_measures_every_visibility_mode_in_the_papers_order():
    assert sorted(MODES) == sorted(m.name for m in VisibilityMode if m is not VisibilityMode.UNSPECIFIED)
    assert MODES == ("RAYCAST", "NO_ANTICIPATION", "ANTICIPATION", "REACTIVE", "FRAMING_ONLY")
    assert [MODE_LABELS[m] for m in MODES[:3]] == ["R", "W", "A"]
