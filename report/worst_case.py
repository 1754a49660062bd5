"""The forecast's worst case over a profile's envelope as recorded with a stored analysis
(`report.stored`): its own module, so that `report.compliance` (which `plan check` reads for its
profiles) imports no numpy."""

from dataclasses import dataclass

from gyrostand.analysis.forecast import EnvelopeWorst, MotionBox


@dataclass(frozen=True)
class WorstCase:
    """The envelope's worst case of the forecast (`envelope_worst`) and what it was sought
    over: found when the analysis is recorded (`report.stored`, for each shipped profile) and
    reused by its reports, which otherwise search again (a bounded Powell search: importing
    scipy.optimize alone takes 0.15 s of a fresh process)."""

    box: MotionBox
    arm_cm: float
    motion: str
    secant_latitude: bool
    worst: EnvelopeWorst
