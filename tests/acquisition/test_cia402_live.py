"""`campaign run` on a CiA 402 stand on a real bus, in real time (`acquisition.cia402_live`):
python-can's `virtual` bus in this process, the simulated stand (`acquisition.cia402_sim_stand`:
drive, CiA 410 inclinometer, NMEA 2000 compass on the platform) in a thread of its own, driven
only by the SYNC that gyrostand produces. A short plan (two short trials, a third with a drive
fault); the checks are numbers against the simulator's truth, read from the campaign's SQLite
file, none on wall-clock timing."""

from __future__ import annotations

import dataclasses
import math
import os
import sqlite3
import threading
import uuid
from contextlib import closing
from pathlib import Path

import pytest

from gyrostand.acquisition.cia402_sim_stand import SimulatedStand, StandThread
from gyrostand.acquisition.runner import run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.plan.model import Plan, parse_plan

# real time, gyrostand's CiA 402 master, the engine and the simulated drive in one process: not
# load-proof (with the drive's and gyrostand's heartbeat every second, on a 2-core host at
# load 11-12 (the test at nice 10, `yes` x2 and the SocketCAN VM beside) 4 runs of 4 failed: the
# drive's first answer later than 2 and 3 s (the master takes it for silent), a trial mis-tracked
# by the cycles the master was late for (14.95 cm measured for 16), all three trials failed
# once); unloaded it passes (111 s at load 5-7). Opt-in with the other real-time tests.
pytestmark = pytest.mark.skipif(
    os.environ.get("GYROSTAND_PROCESS_TESTS") != "1",
    reason="opt-in: make test-processes (real time in one process: not load-proof)",
)

CYCLE_MS = 50  # (a loaded host: the master in Python keeps up; the stand time is the same)
# a master in Python beside the simulated stand in one process, on a loaded host, can stall
# for longer than a lab's 300 ms (the heartbeat consumer is tested in virtual time and the VM)
TIMEOUT_MS = 5000
# the drive's heartbeat, and gyrostand's, every second (lost after 3 s): beside the SocketCAN VM
# in CI the drive's thread starved past 3 x 100 ms in 2 of 4 runs
HEARTBEAT_MS = 1000
SCALE = 1.03  # the platform rolls 3 % more than the encoder counts (the kinematics error)
TRIALS = [(45.0, 20.0, 2.0), (135.0, 16.0, 2.5), (45.0, 12.0, 2.0)]

PLAN = """
[campaign]
operator = "live test"
n_obs = 2
database = "{folder}/live.sqlite"
raw_log_dir = "{folder}/raw"
on_trial_failure = "continue"
acquisition_only = true

[instrument]
model = "test compass"
serial = "LIVE-1"
lp_gcm2s2 = 6.57e6
h1_gcm2s = 1.55e8

[site]
latitude_deg = 46.5
earth_rate_rad_s = 7.3e-5
gravity_cm_s2 = 981.0

[analysis]
start_c = 7.0e7
start_t_s = 0.55

[forecast]
roll_deg = 5.0
arm_cm = 750.0
period_s = 7.0
course_deg = 45.0
latitude_deg = 57.0

[observation]
still_window_s = 2.0
rocking_window_periods = 2

[settle]
band_deg = 5.0
hold_s = 1.0
max_wait_s = 120.0

[tracking]
confirm_s = 10.0

[timeouts]
ack_s = 10.0
bus_silence_s = 10.0

[bus]
simulated = false
interface = "virtual"
channel = "{channel}"
[bus.simulator]
heading_rate_hz = 10.0
[bus.simulator.compass]
undamped_period_s = 20.0
damping_ratio = 0.8
[bus.simulator.inclinometer]
noise_deg = 0.005
[bus.simulator.faults]
amplitude_factor = {scale}

[inclinometer]
protocol = "cia410"
node_id = 4

[stand]
protocol = "cia402"
eds = "sim-drive.eds"
node_id = 2
counts_per_degree = 10000
arm_length_cm = 750
cycle_ms = {cycle_ms}
ramp_s = 1
drive_timeout_ms = {timeout_ms}
drive_heartbeat_ms = {heartbeat_ms}

[compass]
protocol = "nmea2000"
"""

TRIAL = """
[[trials]]
direction_deg = {0}
amplitude_cm = {1}
period_s = {2}
role = "fit"
"""


def live_plan(folder: Path, channel: str) -> Plan:
    text = PLAN.format(
        folder=folder,
        channel=channel,
        scale=SCALE,
        cycle_ms=CYCLE_MS,
        timeout_ms=TIMEOUT_MS,
        heartbeat_ms=HEARTBEAT_MS,
    )
    return parse_plan(text + "".join(TRIAL.format(*t) for t in TRIALS))


def _fault_in_roll(stand: SimulatedStand, roll: int, stop: threading.Event) -> None:
    """An over-current fault of the drive 1 s of its time after roll `roll` began."""
    while not stop.wait(0.05):
        if stand.compass.rolls >= roll:
            drive = stand.drive
            drive.faults = dataclasses.replace(drive.faults, overcurrent_at_s=drive.t_s + 1.0)
            return


def _rows(db: Path, sql: str) -> list[tuple]:
    with closing(sqlite3.connect(db)) as conn:
        return conn.execute(sql).fetchall()


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    folder = tmp_path_factory.mktemp("live")
    plan = live_plan(folder, f"gyrostand-live-{uuid.uuid4().hex}")
    sim = StandThread(plan)
    watcher = threading.Thread(target=_fault_in_roll, args=(sim.stand, 3, sim.stop))
    watcher.start()
    try:
        sessions = open_database(sqlite_url(folder / "live.sqlite"))
        store = CampaignStore.create(sessions, plan)
        answers = {p.id: "yes" for p in plan.prompt}
        result = run_live(plan, store, quiet=True, answers=answers)
    finally:
        sim.close()
        watcher.join()
    return folder / "live.sqlite", result, sim.stand


def test_the_live_campaign_acquires_its_trials_with_the_roll_measured(live):
    db, result, stand = live
    assert (result.trials_completed, result.trials_failed) == (2, 1), result
    # two still and two rocking observations per completed trial, stored
    (n,) = _rows(
        db,
        "SELECT count(*) FROM observation o JOIN series s ON o.series_id = s.id "
        'JOIN trial t ON s.trial_id = t.id WHERE t."index" <= 2',
    )[0]
    assert n == 2 * 2 * 2
    motions = _rows(
        db,
        'SELECT t."index", m.source, m.amplitude_cm, m.amplitude_se_cm, m.period_s FROM '
        "measured_motion m JOIN series s ON m.series_id = s.id JOIN trial t ON s.trial_id = t.id "
        'ORDER BY t."index", m.source',
    )
    felt = {k: (a, tau) for k, (_, _, a, tau) in enumerate(stand.compass.felt, start=1)}
    assert [k for k, *_ in motions] == [1, 1, 2, 2]
    for idx, source, amplitude, se, period in motions:
        K, A, tau = TRIALS[idx - 1]
        # the truth: the amplitude the simulated platform rolled at (fitted by the simulator
        # from its own sampled positions), the encoder's without the kinematics error
        truth = felt[idx][0] * (1.0 if source == "inclinometer" else 1.0 / SCALE)
        assert amplitude == pytest.approx(truth, abs=4 * se + 0.02 * A), (idx, source)
        assert period == pytest.approx(tau, rel=0.01)
        assert math.isfinite(se)
    assert {s for _, s, *_ in motions} == {"inclinometer", "drive position"}


def test_a_drive_fault_fails_its_trial_naming_the_error_and_leaves_the_axis_at_rest(live):
    db, _, stand = live
    errors = _rows(
        db,
        'SELECT t."index", e.kind, e.message FROM event e JOIN trial t ON e.trial_id = t.id '
        "WHERE e.severity = 'error'",
    )
    assert errors == [(3, "drive fault", errors[0][2])] and "0x2310" in errors[0][2]
    (reason,) = _rows(db, 'SELECT failure_reason FROM trial WHERE "index" = 3')[0]
    assert "0x2310" in reason
    assert stand.drive.at_rest and stand.drive.emcy_sent == [0x2310]
