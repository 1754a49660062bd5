"""`python -m gyrostand` and the `gyrostand` command: Ctrl-C at any point of the start-up (the
CLI's imports) or of a command that does not handle it itself is one line and exit code 130,
never a traceback."""

import os

from gyrostand.interrupt import interrupted


def main() -> None:
    # pydantic's plugins (observers of every validation, found in every installed distribution's
    # entry points: ~4 % of `plan check`'s start-up) are not looked for unless the user says so
    os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")
    try:
        from gyrostand.cli import app

        app(prog_name="gyrostand")
    except KeyboardInterrupt:
        interrupted()


if __name__ == "__main__":
    main()
