"""A `gyrostand simulate --schedule` file: read with a pydantic model like the plan, every
problem with its path in one ScheduleError."""

from pathlib import Path

import pytest

from gyrostand.stand.schedule import ScheduleError, Step, load_schedule

GOOD = """
[[step]]
action = "still"
duration_s = 600
[[step]]
action = "rock"
duration_s = 1200.0
direction_deg = 45
amplitude_cm = 24.0
period_s = 6.0
"""


def test_schedule_file_gives_its_steps(tmp_path: Path) -> None:
    path = tmp_path / "schedule.toml"
    path.write_text(GOOD)
    assert load_schedule(path) == [Step("still", 600.0), Step("rock", 1200.0, 45.0, 24.0, 6.0)]


@pytest.mark.parametrize(
    ("text", "problems"),
    [
        (
            '[[step]]\naction = "rock"\nduration_s = -1\nfoo = 2\n'
            '[[step]]\naction = "spin"\nduration_s = "x"\n',
            "[[step]] 1 duration_s: must be >= 0; [[step]] 1 foo: unknown key; "
            "[[step]] 2 action: must be one of 'still', 'rock', not 'spin'; "
            "[[step]] 2 duration_s: must be a finite number",
        ),
        ("x = 1\n", "[[step]]: missing; x: unknown key"),
        ("step = []\n", "[[step]]: must not be empty"),
    ],
)
def test_every_problem_with_its_path(tmp_path: Path, text: str, problems: str) -> None:
    path = tmp_path / "schedule.toml"
    path.write_text(text)
    with pytest.raises(ScheduleError) as caught:
        load_schedule(path)
    assert str(caught.value) == f"{path}: {problems}"
