"""Every shipped scenario loads, and the server's own validation accepts what it builds."""

from __future__ import annotations

import pytest

from camdirector.evaluation.scenario_file import load_scenario, shipped_scenarios
from camdirector.evaluation.toric.suite import PAPER_SCENES, suite_scenarios
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.codec import frame_from_msg, scene_from_request

SHIPPED = shipped_scenarios()
ON_SHARED_DATA = {name for name, path in SHIPPED.items() if "shared/data" in path.read_text()}


def test_the_paper_suite_and_a_real_level_are_shipped():
    assert set(PAPER_SCENES) <= set(SHIPPED)
    assert [p.stem for p in suite_scenarios("paper")] == list(PAPER_SCENES)
    assert ON_SHARED_DATA, "one scenario plays on a level from ../shared/data"


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_scenario_builds_a_valid_session(name, request):
    if name in ON_SHARED_DATA:
        request.getfixturevalue("shared_data")  # skipped with a reason where ../shared/data is absent
    scenario = load_scenario(SHIPPED[name])
    assert scenario.name == name and scenario.notes, "say how the scene follows its source"
    timeline = scenario.timeline(0.5)
    req = scenario.create_session_request(pb.FRAMING_ONLY, timeline=timeline)
    spec = scene_from_request(req, ServerSettings())  # raises DirectorError on anything invalid
    assert len(spec.targets) == len(scenario.targets) and len(spec.objects) == len(scenario.objects)
    movable = {o.id for o in spec.objects if o.dynamic} | {t.id for t in spec.targets}
    static = {o.id for o in spec.objects if not o.dynamic}
    for update in scenario.frame_updates("s", timeline):
        frame_from_msg(update, movable, static)
    # the file's own mode is the paper's method; a run overrides it
    assert scenario.create_session_request().style.visibility == pb.ANTICIPATION
