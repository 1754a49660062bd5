"""Signal analysis of a raw CAN log written by the simulated stand with known noise (stand.simconfig
NoiseParams: exponential correlation sigma, mu; white noise; a spurious harmonic): the fitted
numbers against the simulator's settings, the still stretch found from the stand's status frames,
and `gyrostand analyze --signal --log` with its one-line errors.

Tolerances are about 3 standard deviations of each estimate over 40 simulated records like this
one (3600 s at 10 Hz, mu = 0.2/s): mu 10 %, sigma 3 %, white variance 10 %, harmonic amplitude
1.5 %, its frequency 3e-6 Hz."""

import json
import math
from dataclasses import replace
from pathlib import Path

import can
import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.plan.model import parse_plan
from gyrostand.report.signal import SignalSection
from gyrostand.report.signal_record import log_record, log_signal, still_stretch
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import CompassParams, NoiseParams, SimConfig
from tests.acquisition.harness import plan_text

NOISE = NoiseParams(
    corr_sigma_deg=0.01,
    corr_mu_per_s=0.2,
    white_sigma_deg=0.005,
    spurious_amplitude_deg=0.005,
    spurious_period_s=2.5,
)
STILL_S, ROCK_S, AFTER_S = 3600.0, 200.0, 300.0
runner = CliRunner()


def write_log(path: Path, noise: NoiseParams = NOISE, seed: int = 5) -> Path:
    """Still for STILL_S, rocking for ROCK_S, still again for AFTER_S; every frame to a BLF."""
    config = SimConfig(compass=CompassParams(transient=False), noise=noise, seed=seed)
    stand, codec = StandEngine(config), Codec()
    frames = stand.advance_to(STILL_S)
    for command in (codec.encode_command_set(45.0, 20.0, 5.0), codec.encode_command_start()):
        command.timestamp = stand.stand_time_s
        frames += [command, *stand.receive(command)]
    frames += stand.advance_to(STILL_S + ROCK_S)
    stop = codec.encode_command_stop()
    stop.timestamp = stand.stand_time_s
    frames += [stop, *stand.receive(stop), *stand.advance_to(STILL_S + ROCK_S + AFTER_S)]
    with can.BLFWriter(path) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    return path


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(tmp_path_factory.mktemp("signal") / "still.blf")


@pytest.fixture(scope="module")
def section(log: Path) -> SignalSection:
    return log_signal(log)


def test_the_record_is_the_longest_still_stretch(log: Path, section: SignalSection) -> None:
    start, end = still_stretch(log, Codec())
    assert start == 0.0 and STILL_S * 1000 - 500 <= end < STILL_S * 1000 + 500  # 2 Hz statuses
    record = section.record
    assert record.dt_s == pytest.approx(0.1) and record.filled == 0
    assert record.reading_deg.size == record.frames == round(end / 100) + 1
    assert "longest still stretch" in record.source


def test_fitted_noise_matches_the_simulator(section: SignalSection) -> None:
    noise = section.noise
    exponential = noise.exponential
    assert exponential.decay_per_s == pytest.approx(NOISE.corr_mu_per_s, rel=0.3)
    assert math.sqrt(exponential.variance) == pytest.approx(NOISE.corr_sigma_deg, rel=0.09)
    assert exponential.correlation_time_s == pytest.approx(1 / exponential.decay_per_s)
    # white part: the simulator's white noise plus the 16-bit encoder's quantisation q^2/12
    white = NOISE.white_sigma_deg**2 + NOISE.quantum_deg**2 / 12
    assert exponential.white_variance == pytest.approx(white, rel=0.3)
    (harmonic,) = noise.harmonics.harmonics
    assert harmonic.frequency_hz == pytest.approx(1 / NOISE.spurious_period_s, abs=1e-5)
    assert harmonic.amplitude == pytest.approx(NOISE.spurious_amplitude_deg, rel=0.045)
    assert harmonic.amplitude_from_correlation == pytest.approx(
        NOISE.spurious_amplitude_deg, rel=0.045
    )
    assert harmonic.false_alarm_probability < 1e-6
    assert section.reading_interval_ok  # 0.1 s readings, Delta of seconds
    assert noise.sampling.interval_s > 10 * section.record.dt_s


def test_an_asc_log_gives_the_same_record(tmp_path: Path) -> None:
    stand = StandEngine(SimConfig(compass=CompassParams(transient=False), noise=NOISE, seed=2))
    frames = stand.advance_to(120.0)
    for path, writer in ((tmp_path / "a.blf", can.BLFWriter), (tmp_path / "a.asc", can.ASCWriter)):
        with writer(path) as w:
            for frame in frames:
                w.on_message_received(frame)
    blf, asc = (log_record(tmp_path / name, Codec()) for name in ("a.blf", "a.asc"))
    assert asc.reading_deg.size == blf.reading_deg.size == 1201
    assert asc.reading_deg == pytest.approx(blf.reading_deg, abs=1e-12)


def test_no_harmonic_is_reported_in_plain_noise(tmp_path: Path) -> None:
    quiet = log_signal(write_log(tmp_path / "quiet.blf", replace(NOISE, spurious_amplitude_deg=0)))
    assert quiet.noise.harmonics.harmonics == ()


ACCEPTANCE = "\n[acceptance]\ntolerance_deg = {}\nduration_s = 600.0\nmax_risk = 0.01\n"


def test_acceptance_follows_rice_with_the_fitted_smooth_model(log: Path) -> None:
    plan = parse_plan(plan_text() + ACCEPTANCE.format(0.04))
    verdict = log_signal(log, plan).acceptance
    smooth = log_signal(log).noise.smooth
    sigma2, mu, beta = smooth.variance, smooth.decay_per_s, smooth.frequency_rad_s
    # seed 004 eq 8.88: n = T sigma_v / (pi sigma) e^(-eps^2 / 2 sigma^2), sigma_v^2 = -K''(0)
    n = 600.0 * math.sqrt(mu**2 + beta**2) / math.pi * math.exp(-(0.04**2) / (2 * sigma2))
    assert verdict.excursions.rice.mean_excursions == pytest.approx(n, rel=1e-9)
    assert verdict.risk == pytest.approx(1 - verdict.excursions.p_no_excursion, rel=1e-12)
    assert verdict.verdict == ("PASS" if verdict.risk <= 0.01 else "FAIL")
    eps = verdict.tolerance_for_max_risk_deg
    tighter = log_signal(log, parse_plan(plan_text() + ACCEPTANCE.format(0.98 * eps)))
    looser = log_signal(log, parse_plan(plan_text() + ACCEPTANCE.format(1.02 * eps)))
    assert (tighter.acceptance.verdict, looser.acceptance.verdict) == ("FAIL", "PASS")


def test_cli_text_and_json(log: Path, section: SignalSection) -> None:
    text = runner.invoke(app, ["analyze", "--signal", "--log", str(log)])
    assert text.exit_code == 0, text.output
    for heading in ("CORRELATION", "HIDDEN HARMONICS", "ALLAN", "SAMPLING", "SETTLE", "EXCURSIONS"):
        assert heading in text.stdout
    harmonic = section.noise.harmonics.harmonics[0]
    assert f"{harmonic.frequency_hz:.5f} Hz: amplitude {harmonic.amplitude:.4f} deg" in text.stdout
    result = runner.invoke(app, ["analyze", "--signal", "--log", str(log), "--json"])
    assert result.exit_code == 0
    doc = json.loads(result.stdout)
    assert doc["schema"] == "gyrostand.signal/2"
    assert doc["noise"]["exponential"]["decay_per_s"] == section.noise.exponential.decay_per_s
    assert doc["record"]["n"] == section.record.reading_deg.size
    assert doc["acceptance"] is None and doc["settle"] == []


def test_cli_span_and_plan(log: Path, tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(plan_text() + ACCEPTANCE.format(0.04))
    args = ["analyze", "--signal", "--log", str(log), "--plan", str(plan), "--json"]
    result = runner.invoke(app, [*args, "--from", "3850", "--to", "4100"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["record"]["n"] == 2500  # 3850.0 .. 4099.9 s at 10 Hz: the end is excluded
    assert doc["acceptance"]["criterion"] == {
        "tolerance_deg": 0.04,
        "duration_s": 600.0,
        "max_risk": 0.01,
    }


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--signal"], "--signal needs a CAMPAIGN id or --log FILE"),
        (["--signal", "--log", "missing.blf"], "raw log missing.blf: not found"),
        (["--log", "x.blf"], "--log, --from and --to go with --signal"),
        (["--signal", "--csv", "x.csv"], "not --csv"),
        (["1", "--signal", "--log", "x.blf"], "not both"),
        (["--signal", "--log", "{log}", "--from", "10", "--to", "5"], "empty stand-time span"),
        (["--signal", "--log", "{log}", "--from", "3850", "--to", "3880"], "too short"),
        (["--signal", "--log", "{log}", "--plan", "{bad_plan}"], "[campaign] n_obs: missing"),
        (["--signal", "--log", "{garbage}"], "0 valid heading frames in the whole log"),
        (["--signal", "--log", "{unknown}"], "cannot read it"),
    ],
)
def test_cli_errors_are_one_line(log: Path, tmp_path: Path, args: list[str], message: str) -> None:
    bad_plan, garbage = tmp_path / "bad.toml", tmp_path / "garbage.blf"
    bad_plan.write_text(plan_text().replace("n_obs = 3\n", ""))
    garbage.write_bytes(b"LOGG" + bytes(range(256)) * 4)
    unknown = tmp_path / "frames.xyz"
    unknown.write_text("not a log")
    paths = {"log": log, "bad_plan": bad_plan, "garbage": garbage, "unknown": unknown}
    result = runner.invoke(app, ["analyze", *(a.format(**paths) for a in args)])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gyrostand: error: ")
    assert message in lines[0]
