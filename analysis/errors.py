"""Typed errors of the analysis layer: one `AnalysisError` root, one subclass per kind of bad input.

Every message names the trial or the quantity at fault, so the CLI can print it as one line.
"""


class AnalysisError(ValueError):
    """Root of every error the analysis layer raises for bad input or an unusable design."""


class NonFiniteError(AnalysisError):
    """An input or intermediate quantity is NaN or infinite."""


class TooFewTrialsError(AnalysisError):
    """Fewer observations (trials) than parameters + 1: no residual degrees of freedom."""


class TooFewObservationsError(AnalysisError):
    """A series has N < 2 observations, so its sample variance (eq 2.2) is undefined."""


class ZeroVarianceError(AnalysisError):
    """A variance that must be positive is zero (identical observations, stuck or quantised)."""


class SingularDesignError(AnalysisError):
    """X^T X is singular or nearly so: the parameters cannot be separated by these trials."""


class UnequalDegreesOfFreedomError(AnalysisError):
    """Cochran's test (eq 2.5) needs every variance with the same degrees of freedom."""


class MissingDataError(AnalysisError):
    """A trial lacks a quantity its role needs, or mixes incompatible input forms."""


class ConvergenceError(AnalysisError):
    """Neither Gauss-Newton nor the trust-region fallback reached a solution."""
