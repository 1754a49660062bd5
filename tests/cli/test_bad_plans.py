"""Plans that cannot run, given to `campaign run`: one line naming the table and key at fault,
exit code 2, nothing written. An unknown key in every table of the plan model (the tables are
read from the model, so a new table is covered), values of the wrong type, out of range, beyond
the stand's limits or the simulator's, a design the analysis cannot fit (Potemkin 1982: n >= m +
1 fit trials), string values for simulator knobs, and DBC signals or files that do not exist."""

from __future__ import annotations

import random
import re
import typing
from collections.abc import Iterator
from importlib.resources import files
from pathlib import Path

import pytest
from pydantic import BaseModel

from gyrostand.plan.model import Plan

from .cases import Case, Make, check, ids
from .conftest import Stand

INCLINOMETER_EDS = Path(str(files("gyrostand.devices") / "data" / "sim-inclinometer.eds"))

BOGUS = 'bogus_key = "x"\n'


def plan_edit(*changes: tuple[str, str], append: str = "", prepend: str = "") -> Make:
    """The stand's plan with substitutions (old, new; each old must be there; a line is
    "^key = ...$") and text added; {tmp} in the new text is the test's folder."""

    def make(stand: Stand, tmp: Path) -> Path:
        text = stand.plan.read_text()
        for old, new in changes:
            new = new.replace("{tmp}", str(tmp))
            if old.startswith("^"):
                text, n = re.subn(old, new, text, count=1, flags=re.MULTILINE)
                assert n == 1, old
            else:
                assert old in text, old
                text = text.replace(old, new, 1)
        path = tmp / "bad.toml"
        path.write_text(prepend + text + append)
        return path

    return make


def plan_case(id: str, message: str, *changes: tuple[str, str], **added: str) -> Case:
    args = ("campaign", "run", "{file}", "--db", "{db}", "--quiet")
    return Case(id, args, message, 2, plan_edit(*changes, **added))


# --------------------------------------------------------------------- unknown keys, every table
def _model_in(annotation: object) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        if (found := _model_in(arg)) is not None:
            return found
    return None


def tables(model: type[BaseModel], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Every table of the plan model, as its path: its sub-models and free-form tables."""
    for name, f in model.model_fields.items():
        sub = _model_in(f.annotation)
        if sub is not None:
            yield (*prefix, name)
            yield from tables(sub, (*prefix, name))
        elif typing.get_origin(f.annotation) is dict:
            yield (*prefix, name)


def unknown_key(table: tuple[str, ...]) -> Case:
    if table == ("trials",):
        return plan_case(
            "unknown key in [[trials]]",
            "[[trials]] 1 bogus_key: unknown key",
            ("[[trials]]\n", "[[trials]]\n" + BOGUS),
        )
    if table == ("prompt",):  # an array of tables the base plan does not have
        prompt = '\n[[prompt]]\nid = "mounted"\ntext = "Compass mounted?"\n'
        return plan_case(
            "unknown key in [[prompt]]",
            "[[prompt]] 1 bogus_key: unknown key",
            append=prompt + BOGUS,
        )
    if table[0] == "procedure":  # an array of tables the base plan does not have
        settling = '\n[[procedure]]\nkind = "settling"\n'
        if table == ("procedure",):
            return plan_case(
                "unknown key in [[procedure]]",
                "[[procedure]] 1 bogus_key: unknown key",
                append=settling + BOGUS,
            )
        point = '[[procedure]]\nkind = "rolling"\npoints = [{direction_deg = 45, amplitude_cm = 2, '
        return plan_case(
            "unknown key in [procedure.points]",
            "[procedure.points] bogus_key: unknown key",
            append=settling + point + "period_s = 6, bogus_key = 1}]\n",
        )
    dotted = ".".join(table)
    args = ("campaign", "run", "{file}", "--db", "{db}", "--quiet")
    message = f"[{dotted}] bogus_key: unknown key"
    return Case(f"unknown key in [{dotted}]", args, message, 2, _in_table(f"[{dotted}]\n"))


def _in_table(header: str) -> Make:
    def make(stand: Stand, tmp: Path) -> Path:
        text = stand.plan.read_text()
        if header in text:
            return plan_edit((header, header + BOGUS))(stand, tmp)
        return plan_edit(append=f"\n{header}{BOGUS}")(stand, tmp)

    return make


UNKNOWN_KEYS = [
    *(unknown_key(table) for table in tables(Plan)),
    plan_case("unknown key at the top", "bogus_key: unknown key", prepend=BOGUS),
]

# --------------------------------------------------------------------------------- values
N_OBS = ("n_obs = 3", "n_obs = {}")
K = ("direction_deg = 45.0", "direction_deg = {}")
A = ("amplitude_cm = 24.0", "amplitude_cm = {}")
TAU = ("period_s = 6.0", "period_s = {}")


def sub(change: tuple[str, str], value: str) -> tuple[str, str]:
    return change[0], change[1].format(value)


def faults(text: str) -> str:
    return f"\n[bus.simulator.faults]\n{text}\n"


def compass(text: str) -> tuple[str, str]:
    return "damping_ratio = 0.8\n", f"damping_ratio = 0.8\n{text}\n"


VALUES = [
    # types
    plan_case("n_obs a string", "[campaign] n_obs: must be an integer", sub(N_OBS, '"three"')),
    plan_case("n_obs a float", "[campaign] n_obs: must be an integer", sub(N_OBS, "3.5")),
    plan_case(
        "direction a string", "[[trials]] 1 direction_deg: must be a finite", sub(K, '"north"')
    ),
    plan_case("amplitude a boolean", "[[trials]] 1 amplitude_cm: must be a finite", sub(A, "true")),
    plan_case(
        "operator a number",
        "[campaign] operator: must be a non-empty string",
        ('operator = "test"', "operator = 5"),
    ),
    plan_case(
        "simulated a string",
        "[bus] simulated: must be true or false",
        ("simulated = true", 'simulated = "yes"'),
    ),
    # ranges
    plan_case("n_obs 1", "[campaign] n_obs: must be >= 2", sub(N_OBS, "1")),
    plan_case(
        "n_obs 10**9",
        "[campaign] n_obs: 1000000000 x (30 s window + 0 s spacing) = 347222.2 days",
        sub(N_OBS, str(10**9)),
    ),
    plan_case("n_obs 10**30", "[campaign] n_obs: must be <= 2147483647", sub(N_OBS, str(10**30))),
    plan_case("direction 360", "[[trials]] 1 direction_deg: must be < 360", sub(K, "360.0")),
    plan_case("direction nan", "[[trials]] 1 direction_deg: must be a finite", sub(K, "nan")),
    plan_case("amplitude inf", "[[trials]] 1 amplitude_cm: must be a finite", sub(A, "inf")),
    plan_case("period 0", "[[trials]] 1 period_s: must be > 0", sub(TAU, "0")),
    plan_case(
        "role unknown",
        "[[trials]] 1 role: must be one of 'fit', 'control', not 'fitt'",
        ('role = "fit"', 'role = "fitt"'),
    ),
    plan_case(
        "latitude 90",
        "[site] latitude_deg: must be < 90",
        ("latitude_deg = 46.5", "latitude_deg = 90.0"),
    ),
    plan_case(
        "q 1.5", "[analysis] q: must be < 1", ("start_c = 7.0e7", "start_c = 7.0e7\nq = 1.5")
    ),
    plan_case(
        "course 360",
        "[forecast] course_deg: must be < 360",
        ("course_deg = 45.0", "course_deg = 360.0"),
    ),
    plan_case(
        "spacing negative",
        "[observation] spacing_s: must be >= 0",
        ("spacing_s = 0.0", "spacing_s = -1.0"),
    ),
    plan_case(
        "max_wait below hold",
        "[settle] max_wait_s: must be >= hold_s",
        ("max_wait_s = 3600.0", "max_wait_s = 10.0"),
    ),
    plan_case(
        "estimate without its keys",
        "[settle] undamped_period_s: missing",
        ("max_wait_s = 3600.0", 'max_wait_s = 3600.0\nmethod = "estimate"'),
    ),
    plan_case("ack timeout 0", "[timeouts] ack_s: must be > 0", ("ack_s = 2.0", "ack_s = 0.0")),
    plan_case(
        "raw log format unknown",
        "[campaign] raw_log_format: must be one of 'blf', 'asc', not 'mf4'",
        ('operator = "test"', 'operator = "test"\nraw_log_format = "mf4"'),
    ),
    plan_case(
        "database empty",
        "[campaign] database: must be a non-empty string",
        ("^database = .*$", 'database = ""'),
    ),
    plan_case(
        "duplicate key", "TOML syntax: Cannot overwrite a value", (N_OBS[0], "n_obs = 3\nn_obs = 4")
    ),
    Case(
        "plan not utf-8",
        ("campaign", "run", "{file}", "--db", "{db}"),
        "cannot read the file",
        2,
        lambda stand, tmp: _write(tmp / "bad.toml", b"\xff\xfe" + stand.plan.read_bytes()),
    ),
    # limits of the stand and a design the analysis can fit
    plan_case("amplitude beyond the stand", "80 exceeds the stand's limit 50 cm", sub(A, "80.0")),
    plan_case("period below the stand", "1 is below the stand's limit 2 s", sub(TAU, "1.0")),
    plan_case("period beyond the stand", "30 exceeds the stand's limit 20 s", sub(TAU, "30.0")),
    plan_case(
        "amplitude beyond [stand]",
        "[[trials]] 1 amplitude_cm: 24 exceeds the stand's limit 10 cm",
        append="\n[stand]\nmax_amplitude_cm = 10.0\n",
    ),
    plan_case(
        "[stand] periods crossed",
        "[stand] max_period_s: must be >= min_period_s",
        append="\n[stand]\nmin_period_s = 10.0\nmax_period_s = 5.0\n",
    ),
    plan_case(
        "fewer than 3 fit trials",
        "1 fit trial, but the analysis needs at least 3 (m + 1 for the m = 2 parameters",
        ("acquisition_only = true", "acquisition_only = false"),
    ),
    plan_case(
        "no fit trial",
        "at least one trial must have role 'fit'",
        ('role = "fit"', 'role = "control"'),
    ),
    # simulator knobs: strings, then values it cannot simulate or put in a frame
    *(
        plan_case(
            f"{knob} a string",
            f"[bus.simulator.faults] {knob}: must be {what}",
            append=faults(f'{knob} = "{value}"'),
        )
        for knob, value, what in (
            ("drop_rate", "lots", "a finite number"),
            ("stuck_at_s", "later", "a finite number"),
            ("no_ack", "yes", "true or false"),
            ("compass_fault_bits", "0x04", "an integer"),
        )
    ),
    plan_case(
        "heading rate a string",
        "[bus.simulator] heading_rate_hz: must be a finite number",
        ("heading_rate_hz = 2.0", 'heading_rate_hz = "fast"'),
    ),
    plan_case(
        "drop rate 1.5",
        "[bus.simulator.faults] drop_rate: must be a probability in [0, 1]",
        append=faults("drop_rate = 1.5"),
    ),
    plan_case(
        "stuck at a negative time",
        "[bus.simulator.faults] stuck_at_s: must be a number >= 0, got -5.0",
        append=faults("stuck_at_s = -5.0\nstuck_for_s = 10.0"),
    ),
    plan_case(
        "silence for a negative time",
        "[bus.simulator.faults] silence_for_s: must be a number >= 0, got -3.0",
        append=faults("silence_at_s = 10.0\nsilence_for_s = -3.0"),
    ),
    plan_case(
        "fault bits beyond the frame",
        "[bus.simulator.faults] compass_fault_bits: would put 256 in GYRO_STATUS.FAULT_BITS, "
        "outside [0, 255]",
        append=faults("compass_fault_bits = 256"),
    ),
    plan_case(
        "amplitude factor negative",
        "[bus.simulator.faults] amplitude_factor: must be a number >= 0, got -1.0",
        append=faults("amplitude_factor = -1.0"),
    ),
    plan_case(
        "amplitude factor beyond the frame",
        "[bus.simulator.faults] amplitude_factor: would put 1000 in STAND_MOTION.AMPLITUDE",
        append=faults("amplitude_factor = 20.0"),
    ),
    plan_case(
        "heading rate beyond whole ms",
        "[bus.simulator] heading_rate_hz: must be <= 1000",
        ("heading_rate_hz = 2.0", "heading_rate_hz = 1e9"),
    ),
    plan_case(
        "gravity 0",
        "[bus.simulator.compass] g_cm_s2: must be a positive number, got 0.0",
        compass("g_cm_s2 = 0.0"),
    ),
    plan_case(
        "latitude 95",
        "[bus.simulator.compass] latitude_deg: must be in (-90, 90)",
        compass("latitude_deg = 95.0"),
    ),
    plan_case(
        "fluid temperature beyond the frame",
        "[bus.simulator.compass] fluid_temp_c: would put 500 in GYRO_STATUS.FLUID_TEMP",
        compass("fluid_temp_c = 500.0"),
    ),
    plan_case(
        "noise sigma negative",
        "[bus.simulator.noise] white_sigma_deg: must be a number >= 0, got -1.0",
        append="\n[bus.simulator.noise]\nwhite_sigma_deg = -1.0\n",
    ),
    plan_case(
        "simulated stand periods crossed",
        "[bus.simulator.stand] max_period_s: must be >= min_period_s",
        append="\n[bus.simulator.stand]\nmin_period_s = 30.0\n",
    ),
    # the lab's DBC and signal map
    *(
        plan_case(
            f"signal {ref}",
            message,
            ("[bus]\n", f'[signals]\nheading = "{ref}"\n\n[bus]\n'),
        )
        for ref, message in (
            ("NOPE.HEADING", "signals.heading: no message 'NOPE' in the DBC"),
            ("GYRO_HEADING.NOPE", "signals.heading: message GYRO_HEADING has no signal 'NOPE'"),
            ("HEADING", "signals.heading: expected MESSAGE.SIGNAL, got 'HEADING'"),
        )
    ),
    *(
        plan_case(
            f"dbc {what}",
            "cannot load DBC",
            ("[bus]\n", f'[protocol]\ndbc_path = "{path}"\n\n[bus]\n'),
        )
        for what, path in (
            ("missing", "{tmp}/none.dbc"),
            ("of an unknown format", str(Path(__file__).with_name("conftest.py"))),
            ("a folder", str(Path(__file__).parent)),
        )
    ),
    # the heading source ([compass], docs/instruments.md)
    *(
        plan_case(f"compass {what}", message, append=f"\n[compass]\n{table}\n")
        for what, table, message in (
            (
                "protocol unknown",
                'protocol = "nmea0183"',
                "[compass] protocol: must be one of 'gyrostand', 'dbc', 'nmea2000', 'iec61162', "
                "'cia406', not 'nmea0183'",
            ),
            (
                "dbc without a DBC",
                'protocol = "dbc"',
                '[compass] protocol: protocol = "dbc" needs the lab\'s DBC ([protocol] dbc_path)',
            ),
            (
                "gyrostand on a port",
                'port = "/dev/ttyUSB0"',
                '[compass] port: not with protocol = "gyrostand" (the heading frame is in the '
                "stand's DBC, on the stand's bus)",
            ),
            (
                "serial with a CAN channel",
                'protocol = "iec61162"\nport = "/dev/ttyUSB0"\nchannel = "can1"',
                '[compass] channel: not with protocol = "iec61162" (a serial port)',
            ),
            (
                "nmea2000 with a baud rate",
                'protocol = "nmea2000"\nbaud = 38400',
                '[compass] baud: not with protocol = "nmea2000" (CAN)',
            ),
            (
                "nmea2000 NAME not hexadecimal",
                'protocol = "nmea2000"\nname = "gyro"',
                "[compass] name: must be the 64-bit NAME in hexadecimal",
            ),
            (
                "nmea2000 channel without interface",
                'protocol = "nmea2000"\nchannel = "can1"',
                "[compass] interface: missing (the compass's own bus needs one)",
            ),
            (
                "nmea2000 interface without channel",
                'protocol = "nmea2000"\ninterface = "socketcan"',
                '[compass] channel: missing (the compass\'s own bus, e.g. "can1")',
            ),
            (
                "a real own bus beside the simulated stand",
                'protocol = "nmea2000"\ninterface = "socketcan"\nchannel = "can1"',
                "[compass] interface: beside the simulated stand the compass's own bus is "
                '"virtual"',
            ),
            (
                "cia406 without its node id",
                'protocol = "cia406"\ncounts_per_revolution = 8192',
                '[compass] node_id: missing (protocol = "cia406")',
            ),
            (
                "cia406 without a resolution or an EDS",
                'protocol = "cia406"\nnode_id = 5',
                '[compass] counts_per_revolution: missing (protocol = "cia406" without an eds: '
                "the encoder's 0x6001)",
            ),
            (
                "cia406 node id beyond CANopen's",
                'protocol = "cia406"\nnode_id = 128\ncounts_per_revolution = 8192',
                "[compass] node_id: must be <= 127",
            ),
            (
                "cia406 direction unknown",
                'protocol = "cia406"\nnode_id = 5\ncounts_per_revolution = 8192\ndirection = "cw"',
                "[compass] direction: must be one of 'clockwise', 'counterclockwise', not 'cw'",
            ),
            (
                "encoder keys with another protocol",
                'protocol = "nmea2000"\nnode_id = 5',
                '[compass] node_id: not with protocol = "nmea2000" (cia406)',
            ),
            (
                "cia406 EDS missing",
                'protocol = "cia406"\nnode_id = 5\neds = "none.eds"',
                "[compass] eds: EDS none.eds: [Errno 2] No such file or directory",
            ),
            (
                "cia406 EDS without the position in a TPDO",
                f'protocol = "cia406"\nnode_id = 5\neds = "{INCLINOMETER_EDS}"',
                f"[compass] eds: EDS {INCLINOMETER_EDS}: no TPDO maps the position value 0x6004",
            ),
            (
                "cia406 node id whose EMCY is a stand frame",
                'protocol = "cia406"\nnode_id = 1\ncounts_per_revolution = 8192',
                "[compass] node_id: the encoder's EMCY 0x081 is the stand's frame STAND_ACK (DBC): "
                "give the encoder another node id",
            ),
        )
    ),
    plan_case(
        "nmea2000 on a real bus in virtual time",
        '[compass] protocol: a compass timed by reception needs timing = "realtime" on a real bus',
        ("simulated = true", 'simulated = false\ninterface = "virtual"\ntiming = "virtual"'),
        append='\n[compass]\nprotocol = "nmea2000"\n',
    ),
    plan_case(
        "nmea2000 on a bus of its own that is the stand's",
        "[compass] channel: the stand's bus ([bus]): leave interface and channel out",
        ("simulated = true", 'simulated = false\ninterface = "virtual"\nchannel = "can0"'),
        append='\n[compass]\nprotocol = "nmea2000"\ninterface = "virtual"\nchannel = "can0"\n',
    ),
    plan_case(
        "iec61162 on the simulated stand in real time",
        '[compass] protocol: "iec61162" on the simulated stand needs [bus] timing = "virtual"',
        ("simulated = true", 'simulated = true\ntiming = "realtime"'),
        append='\n[compass]\nprotocol = "iec61162"\n',
    ),
    plan_case(
        "iec61162 on a real bus without its port",
        '[compass] port: missing (the compass\'s serial port, e.g. "/dev/ttyUSB0")',
        ("simulated = true", 'simulated = false\ninterface = "virtual"'),
        append='\n[compass]\nprotocol = "iec61162"\n',
    ),
    plan_case(
        "iec61162 on a real bus in virtual time",
        '[compass] protocol: a compass timed by reception needs timing = "realtime" on a real bus',
        ("simulated = true", 'simulated = false\ninterface = "virtual"\ntiming = "virtual"'),
        append='\n[compass]\nprotocol = "iec61162"\nport = "/dev/ttyUSB0"\n',
    ),
    plan_case(
        "cia402 on a real bus without the drive's EDS file",
        "[stand] eds: no file drives/none.eds (the drive's EDS, from its maker)",
        ("simulated = true", 'simulated = false\ninterface = "virtual"'),
        append='\n[stand]\nprotocol = "cia402"\neds = "drives/none.eds"\nnode_id = 2\n'
        'counts_per_degree = 10000\narm_length_cm = 50\n[compass]\nprotocol = "nmea2000"\n',
    ),
    # the stand's protocol ([stand], docs/instruments.md)
    *(
        plan_case(f"stand {what}", message, append=f"\n[stand]\n{table}\n")
        for what, table, message in (
            (
                "protocol unknown",
                'protocol = "ethercat"',
                "[stand] protocol: must be one of 'gyrostand', 'cia402', not 'ethercat'",
            ),
            (
                "cia402 without its drive",
                'protocol = "cia402"\neds = "drive.eds"\nnode_id = 2\narm_length_cm = 50',
                '[stand] counts_per_degree: missing (protocol = "cia402")',
            ),
            (
                "cia402 node id out of range",
                'protocol = "cia402"\neds = "d.eds"\nnode_id = 128\n'
                "counts_per_degree = 1e4\narm_length_cm = 50",
                "[stand] node_id: must be <= 127",
            ),
            (
                "drive keys on a gyrostand stand",
                "node_id = 2",
                '[stand] node_id: not with protocol = "gyrostand" (a CiA 402 drive\'s)',
            ),
            (
                "cia402 with the stand's heading frame",
                'protocol = "cia402"\neds = "drive.eds"\nnode_id = 2\n'
                "counts_per_degree = 10000\narm_length_cm = 50",
                '[compass] protocol: a "cia402" stand has no clock to put in a heading frame',
            ),
        )
    ),
    Case(
        "dbc garbage",
        ("campaign", "run", "{file}", "--db", "{db}"),
        "cannot load DBC",
        2,
        lambda stand, tmp: _garbage_dbc(stand, tmp),
    ),
]


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _garbage_dbc(stand: Stand, tmp: Path) -> Path:
    dbc = _write(tmp / "lab.dbc", bytes(random.Random(3).randrange(256) for _ in range(2000)))
    return plan_edit(("[bus]\n", f'[protocol]\ndbc_path = "{dbc}"\n\n[bus]\n'))(stand, tmp)


PLANS = UNKNOWN_KEYS + VALUES


@pytest.mark.parametrize("case", PLANS, ids=ids(PLANS))
def test_bad_plan_is_one_line_and_touches_nothing(case: Case, stand: Stand, tmp_path: Path):
    check(case, stand, tmp_path, stand.db_copy(tmp_path))


def test_every_table_has_an_unknown_key_case() -> None:
    assert len(UNKNOWN_KEYS) == len(list(tables(Plan))) + 1 >= 22
