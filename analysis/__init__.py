"""Analysis: pure computation of the seed-000 method and report rendering (no bus, no database).

The two public entry points are importable from here (loaded lazily, so `import analysis` stays
cheap): `cochran_critical(q, nu, k)` and `fit_nonlinear(model, x, y, theta0, ...)`.
"""

from importlib import import_module
from typing import Any

_EXPORTS = {
    "cochran_critical": "gyrostand.analysis.cochran",
    "cochran_test": "gyrostand.analysis.cochran",
    "fit_nonlinear": "gyrostand.analysis.nlsq",
    "FitResult": "gyrostand.analysis.nlsq",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'analysis' has no attribute {name!r}")
