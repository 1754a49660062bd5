"""`python -m gyrostand` and the `gyrostand` command: Ctrl-C at any point of the start-up (the
CLI's imports) or of a command that does not handle it itself is one line and exit code 130,
never a traceback."""

from gyrostand.interrupt import interrupted


def main() -> None:
    try:
        from gyrostand.cli import app

        app(prog_name="gyrostand")
    except KeyboardInterrupt:
        interrupted()


if __name__ == "__main__":
    main()
