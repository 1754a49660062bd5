"""The worked example of seed 000 (Potemkin 1982): constants, start, admissible region, stopping
thresholds and ship forecast, as the paper states them (CGS units)."""

from gyrostand.analysis.campaign import AdmissibleRegion
from gyrostand.analysis.forecast import ShipConditions
from gyrostand.analysis.gyro_model import KnownConstants

CONSTANTS = KnownConstants(
    lP_gcm2s2=6.57e6,
    H1_gcm2s=1.55e8,
    earth_rate_rad_s=7.3e-5,
    gravity_cm_s2=981.0,
    latitude_deg=46.5,
)
START = (7e7, 0.55)  # C0 (g cm^2 s^-2), T0 (s): mid-points of the admissible region
ADMISSIBLE = AdmissibleRegion(
    C_gcm2s2=(2e7, 12e7), T_s=(0.1, 1.0), source="of the example of Potemkin (1982)"
)
EPS = {"C_gcm2s2": 0.01e7, "T_s": 0.01}  # the paper's epsilon_1, epsilon_2 of eq 1.8
# Roll 5 deg at h = 7.5 m, tau = 7 s, course 45 deg, latitude 57 deg; the paper rounds
# A = theta0 h = 0.087265 x 750 = 65.45 cm to 65 cm, and its alpha_p = -2.322 deg uses 65 cm.
FORECAST = ShipConditions(
    roll_deg=5.0,
    arm_cm=750.0,
    period_s=7.0,
    course_deg=45.0,
    latitude_deg=57.0,
    motion="roll",
    amplitude_cm=65.0,
)
