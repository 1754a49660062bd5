"""The commanded roll: closed-form checks of the ramps and the kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrostand.devices.roll_trajectory import Kinematics, RollTrajectory

ROLL = RollTrajectory(amplitude_deg=6.0, period_s=4.0, ramp_s=5.0, stop_at_s=30.0)


def test_the_axis_starts_and_ends_at_rest():
    t = np.array([0.0, -1.0, ROLL.end_s, ROLL.end_s + 3.0])
    assert np.all(ROLL.position_deg(t) == 0.0)
    assert np.all(ROLL.velocity_deg_s(t) == 0.0)


def test_between_the_ramps_it_is_the_sinusoid():
    t = np.linspace(ROLL.ramp_s, ROLL.stop_at_s, 501)
    w = 2 * math.pi / ROLL.period_s
    np.testing.assert_allclose(ROLL.position_deg(t), 6.0 * np.sin(w * t), atol=1e-12)
    np.testing.assert_allclose(ROLL.velocity_deg_s(t), 6.0 * w * np.cos(w * t), atol=1e-12)


@pytest.mark.parametrize("edge", [0.0, ROLL.ramp_s, ROLL.stop_at_s, ROLL.end_s])
def test_position_and_velocity_are_continuous_at_the_ramps(edge):
    h = 1e-7
    for f in (ROLL.position_deg, ROLL.velocity_deg_s):
        left, right = f(np.array([edge - h, edge + h]))
        assert abs(right - left) < 1e-5
    # acceleration too: the velocity's slopes either side agree (quintic ramps)
    v = ROLL.velocity_deg_s(np.array([edge - 2e-4, edge - 1e-4, edge + 1e-4, edge + 2e-4]))
    assert abs((v[1] - v[0]) - (v[3] - v[2])) < 1e-5


def test_velocity_is_the_derivative_of_position():
    t = np.linspace(-1.0, ROLL.end_s + 1.0, 40_001)
    numeric = np.gradient(ROLL.position_deg(t), t)
    np.testing.assert_allclose(ROLL.velocity_deg_s(t)[1:-1], numeric[1:-1], atol=2e-5)


def test_a_stop_during_the_start_ramp_is_smooth_and_ends_at_rest():
    early = RollTrajectory(6.0, 4.0, 5.0).stopped_at(2.0)
    assert early.end_s == 7.0
    t = np.linspace(0.0, 9.0, 90_001)
    numeric = np.gradient(early.position_deg(t), t)
    np.testing.assert_allclose(early.velocity_deg_s(t)[1:-1], numeric[1:-1], atol=2e-5)
    assert early.position_deg(np.array([7.0]))[0] == 0.0
    assert early.stopped_at(5.0).stop_at_s == 2.0  # an earlier stop stays


def test_kinematics_arc_at_the_arm():
    k = Kinematics(counts_per_degree=10_000.0, arm_length_cm=100.0)
    assert k.amplitude_deg(10.0) == pytest.approx(math.degrees(0.1))
    assert k.amplitude_cm(k.amplitude_deg(7.5)) == pytest.approx(7.5)
