"""A tiny visibility cell is refused before anything is allocated (issue 10 item 3)."""

from __future__ import annotations

import pytest

from piste.errors import ConfigError
from piste.pipeline.visibility import compute_visibility
from piste.world.course import default_course


def test_tiny_cell_refused_before_allocating():
    net = default_course(0)
    with pytest.raises(ConfigError, match=r"visibility: a cell of 0\.01 m .* GiB .*larger visibility\.cell"):
        compute_visibility(net, cell=0.01)
