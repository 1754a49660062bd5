"""kill -9 at 30 random moments per campaign, over several simulator seeds (issue 18): every
killed-and-resumed campaign must end equal to its uninterrupted run, row for row, with its raw
log segments read in order equal to the uninterrupted log (tests/acquisition/killing.py says
what is compared). Prints one row per seed; exits 1 when any campaign differs.

Run: .venv/bin/python validation/kill_resume.py [--kills 30] [--seeds 1 2 3]
"""

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests package

from gyrostand.acquisition import bus  # noqa: E402
from tests.acquisition.killing import kill_and_resume, small_containers  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=30)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = parser.parse_args()
    bus.raw_log_writer = small_containers  # the forked runs inherit it
    print(
        f"{'seed':>4} {'kills':>5} {'segments':>8} {'frames in killed logs':>21} {'s':>6}  result"
    )
    failed = 0
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            run = kill_and_resume(Path(tmp), args.kills, seed)
        killed_frames = sum(s.frames or 0 for s in run.segments[:-1])
        result = "equal to the uninterrupted run" if not run.problems else "; ".join(run.problems)
        failed += bool(run.problems)
        print(
            f"{seed:>4} {run.kills:>5} {len(run.segments):>8} {killed_frames:>21} "
            f"{run.seconds:>6.1f}  {result}"
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
