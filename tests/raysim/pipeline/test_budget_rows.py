"""budget_rows from Python refuses what the CLI's parser refuses (it answered -0.01 dB with the
budget of +0.01, NaN with a NaN total, 2.5 readings with 2.5 readings per point)."""

import numpy as np
import pytest

from raysim.pipeline.budget import budget_rows
from solver.errors import SolverError


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"levels": [-0.01]}, "--noise-db values must lie in"),
    ({"levels": [float("nan")]}, "--noise-db values must lie in"),
    ({"levels": [0.0]}, "--noise-db values must lie in"),
    ({"levels": [100.0]}, "--noise-db values must lie in"),
    ({"levels": "0.01"}, "--noise-db values must lie in"),
    ({"levels": []}, "--noise-db values must lie in"),
    ({"levels": [0.01], "readings": 2.5}, "--readings must be an integer"),
    ({"levels": [0.01], "readings": "4"}, "--readings must be an integer"),
    ({"levels": [0.01], "rim": 8.5}, "--rim needs at least 8"),
    ({"levels": [0.01], "rim": -8}, "--rim needs at least 8"),
])
def test_bad_budget_requests_are_refused(kwargs, says):
    with pytest.raises(SolverError, match=says):
        budget_rows("scan_demo", **kwargs)


def test_a_good_request_still_answers():
    (row,) = budget_rows("scan_demo", [0.01], readings=4)
    assert row.readings == 4
    # numpy levels and counts, as a script passes them
    rows = budget_rows("scan_demo", np.array([0.01, 0.02]), readings=np.int64(4))
    assert [r.noise_db for r in rows] == [0.01, 0.02]
