"""Warp's mathematical constants in Python scope (wp.pi, wp.PI, wp.e, ...): float values, the
same names the kernel language knows (docs/builtins.md)."""
import math

__all__ = [
    "E", "HALF_PI", "INF", "LN2", "LN10", "LOG2E", "LOG10E", "NAN", "PHI", "PI", "TAU",
    "e", "half_pi", "inf", "ln2", "ln10", "log2e", "log10e", "nan", "phi", "pi", "tau",
]

E = e = 2.71828182845904523536
LOG2E = log2e = 1.44269504088896340736
LOG10E = log10e = 0.43429448190325182765
LN2 = ln2 = 0.69314718055994530942
LN10 = ln10 = 2.30258509299404568402
PHI = phi = 1.61803398874989484820
PI = pi = 3.14159265358979323846
HALF_PI = half_pi = 1.57079632679489661923
TAU = tau = 6.28318530717958647692
INF = inf = math.inf
NAN = nan = math.nan
