"""Shared fixtures. Fast unit tests run by default (``make test``); long integration checks are
marked ``@pytest.mark.slow`` and run with ``make test-slow``."""

from __future__ import annotations

import pytest

from tests.support import material as _material


@pytest.fixture
def dp_material():
    """Factory ``dp_material(form, hardening, **overrides)`` of typical Drucker-Prager materials."""
    return _material
