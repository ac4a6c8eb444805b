"""KuramotoGroup refuses natural frequencies no human movement has."""

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2
from cogblocks.sync.group import MAX_OMEGA, KuramotoGroup


@pytest.mark.parametrize("omega", [[1e308, 2.0], [2.0, -1e308], [1.0, MAX_OMEGA * 1.01]])
def test_a_frequency_outside_the_plausible_range_is_refused_naming_it(omega):
    with pytest.raises(ValueError, match=r"KuramotoGroup: omega must lie in \[-100, 100\] rad/s") as caught:
        KuramotoGroup(omega, 1.0)
    assert "Hz" in str(caught.value)  # the range is also said in the unit people count movements in


def test_the_range_holds_every_bundled_group_and_keeps_one_tick_below_one_radian():
    for group in TABLE2.values():
        KuramotoGroup(group.omega, group.gain)
    KuramotoGroup([-MAX_OMEGA, MAX_OMEGA], 1.0)  # the bounds themselves are allowed
    assert MAX_OMEGA * 0.01 <= 1.0  # at the 10 ms base step a phase moves at most 1 rad per tick
    assert max(np.max(np.abs(g.omega)) for g in TABLE2.values()) < MAX_OMEGA / 5
