"""Forecasts (eqs 2.10-2.11): ship conventions, the vectorised grid, the predictor round trip."""

import json
from pathlib import Path

import numpy as np
import pytest

from gyrostand.analysis import paper_example as paper
from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.csv_input import read_trials_csv
from gyrostand.analysis.errors import AnalysisError, NonFiniteError
from gyrostand.analysis.forecast import Predictor, ShipConditions, forecast_grid, forecast_ship

CSV = Path(__file__).resolve().parents[2] / "examples" / "paper.csv"


@pytest.fixture(scope="module")
def predictor() -> Predictor:
    return analyze_campaign(read_trials_csv(CSV), paper.CONSTANTS, start=paper.START).predictor


def ship(**changes: object) -> ShipConditions:
    fields = {
        "roll_deg": 5.0,
        "arm_cm": 750.0,
        "period_s": 7.0,
        "course_deg": 45.0,
        "latitude_deg": 57.0,
        **changes,
    }
    return ShipConditions(**fields)


def test_amplitude_is_the_arc_of_the_roll() -> None:
    assert ship().effective_amplitude_cm == pytest.approx(0.0872665 * 750, rel=1e-6)
    assert ship(amplitude_cm=65.0).effective_amplitude_cm == 65.0


def test_rolling_and_pitching_directions(predictor: Predictor) -> None:
    assert ship().direction_deg == 135.0
    assert ship(motion="pitch").direction_deg == 45.0
    roll, pitch = forecast_ship(predictor, ship()), forecast_ship(predictor, ship(motion="pitch"))
    assert roll.alpha_deg == pytest.approx(-pitch.alpha_deg)  # sin 2(K + 90) = -sin 2K
    # port or starboard, north or south course: K and K + 180 give the same error
    opposite = forecast_ship(predictor, ship(course_deg=225.0))
    assert opposite.alpha_deg == pytest.approx(roll.alpha_deg)


def test_exact_amplitude_forecast(predictor: Predictor) -> None:
    """Unrounded A = 65.45 cm: alpha scales with A^2 from the paper's rounded 65 cm."""
    rounded = forecast_ship(predictor, ship(amplitude_cm=65.0))
    exact = forecast_ship(predictor, ship())
    assert exact.alpha_deg == pytest.approx(rounded.alpha_deg * (65.4498 / 65.0) ** 2, rel=1e-4)


def test_mean_of_n_variant_is_narrower(predictor: Predictor) -> None:
    f = forecast_ship(predictor, ship())
    assert f.se_mean_deg**2 == pytest.approx(f.se_deg**2 - predictor.s2_r * (1 - 1 / 5))


def test_grid_matches_pointwise_forecasts(predictor: Predictor) -> None:
    grid = forecast_grid(
        predictor,
        course_deg=np.arange(0, 360, 30),
        roll_deg=[3, 5, 10],
        period_s=[6, 7, 9],
        latitude_deg=[0, 57, 70],
        arm_cm=750.0,
    )
    assert grid.alpha_deg.shape == (12, 3, 3, 3)
    for i, j, k, m in [(1, 1, 1, 1), (4, 2, 0, 2), (11, 0, 2, 0)]:
        point = forecast_ship(
            predictor,
            ship(
                course_deg=grid.course_deg[i],
                roll_deg=grid.roll_deg[j],
                period_s=grid.period_s[k],
                latitude_deg=grid.latitude_deg[m],
            ),
        )
        assert grid.alpha_deg[i, j, k, m] == pytest.approx(point.alpha_deg)
        assert grid.half_width_deg[i, j, k, m] == pytest.approx(point.half_width_deg)
    frame = grid.to_frame()
    assert len(frame) == 12 * 27
    assert np.all(frame.lower_deg <= frame.upper_deg)


def test_predictor_round_trips_through_json(predictor: Predictor) -> None:
    again = Predictor.from_dict(json.loads(json.dumps(predictor.to_dict())))
    assert again == predictor


def test_bad_ship_conditions() -> None:
    with pytest.raises(AnalysisError, match="motion 'heave'"):
        ship(motion="heave")
    with pytest.raises(NonFiniteError, match="course_deg"):
        ship(course_deg=float("nan"))
    with pytest.raises(AnalysisError, match="latitude 90"):
        ship(latitude_deg=90.0)
