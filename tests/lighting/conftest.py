"""Fixtures for the lighting tests; helpers live in ``lighting_nets.py``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # for `from lighting_nets import ...`

from lighting_nets import hill_net, make_lights  # noqa: E402


@pytest.fixture
def hill():
    return hill_net()


@pytest.fixture
def lights():
    return make_lights()
