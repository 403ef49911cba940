"""Bad rotational input on many bodies is still one line: the first offending body and how many."""

from __future__ import annotations

import numpy as np
import pytest
from steplab.physics.rigid_body import InertiaError, RotationModel, check_orientation


@pytest.mark.parametrize("bad, expected", [
    ([-1.0, 1.0, 1.0], "inertia must be > 0 kg m^2 in every moment, got [-1.0, 1.0, 1.0] (row 70, the first of 2 "
                       "such among 100000 bodies)"),
    ([1.0, 1.0, 3.0], "inertia [1.0, 1.0, 3.0] (row 70, the first of 2 such among 100000 bodies) breaks the "
                      "triangle inequality"),
    ([np.inf, 1.0, 1.0], "inertia must be finite, got [inf, 1.0, 1.0] (row 70, the first of 2 such"),
])
def test_bad_inertia_of_many_bodies_is_one_short_line(bad, expected):
    inertia = np.ones((100_000, 3))
    inertia[70] = inertia[99_000] = bad
    with pytest.raises(InertiaError) as err:
        RotationModel(inertia)
    message = str(err.value)
    assert message.startswith(expected) and "\n" not in message and len(message) < 200


def test_bad_orientation_of_many_bodies_is_one_short_line():
    q = np.tile([1.0, 0.0, 0.0, 0.0], (100_000, 1))
    q[12] = 0.0
    with pytest.raises(InertiaError, match=r"got \[0.0, 0.0, 0.0, 0.0\] \(row 12, the first of 1 such among "
                                           r"100000 bodies\)$"):
        check_orientation(q)


def test_one_bad_body_keeps_its_short_message():
    with pytest.raises(InertiaError, match=r"^inertia must be > 0 kg m\^2 in every moment, got \[0.0, 1.0, 1.0\]$"):
        RotationModel(np.array([0.0, 1.0, 1.0]))
