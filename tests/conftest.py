"""Shared pytest set-up. The `socketcan` marker, its skip and the `socketcan_channel` fixture come
from gyrostand's own pytest plugin (`gyrostand.pytest_plugin`), as users' tests get them;
`pytester` runs users' test files against it (tests/plugin)."""

pytest_plugins = ["pytester"]
