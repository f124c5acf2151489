"""Hypothesis profiles of the property-based tests (imported by tests/test_oracle_properties.py).

* ``ci`` (the default): fixed seed (``derandomize``), no example database (a CI run never replays
  examples another run saved), a modest example count, so the suite's property tests cost under a
  minute on two cores once the kernels are compiled. Failing examples print a reproduction blob.
* ``slow``: many more random examples, with the example database (``.hypothesis/``, git-ignored),
  so a failure found once is replayed first next time. The tests marked ``@pytest.mark.slow`` run
  with it (the suite runs ``-m "not slow"``).

No test uses Hypothesis' global profile: each test takes its settings from :func:`profile`, so
the suite's run is the same wherever it runs (no environment variable changes it).
"""
from __future__ import annotations

from hypothesis import HealthCheck, settings

#: a generated case builds a dozen structures: slow by Hypothesis' standards, and never flaky
_COMMON = dict(deadline=None, print_blob=True,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

settings.register_profile("ci", max_examples=25, derandomize=True, database=None, **_COMMON)
settings.register_profile("slow", max_examples=600, **_COMMON)

def profile(name: str = "ci") -> settings:
    """The registered profile ``name`` (default ``ci``), to use as a test decorator."""
    return settings.get_profile(name)
