"""load_tests/program_phases.py's command line refuses phases outside a row and rates that are not
positive before it imports anything. (A run, a minute of eval-match per phase, is not run here:
the phase's grid is tests/matches/test_quakeworld_mvd.py's, the bars tests/load_tests/
test_cast_program.py's.)"""

from __future__ import annotations

import pytest

from load_tests.program_phases import main


@pytest.mark.parametrize(
    "args, says",
    [
        (["--phases", "1.0"], "--phases"),
        (["--phases", "-0.25,0.5"], "--phases"),
        (["--phases", ""], "--phases"),
        (["--rates", "0"], "--rates"),
        (["--end-s", "0"], "--end-s"),
    ],
)
def test_a_phase_outside_a_row_or_a_rate_not_positive_is_refused(args, says, capsys):
    with pytest.raises(SystemExit) as exited:
        main(args)
    assert exited.value.code == 2 and says in capsys.readouterr().err
