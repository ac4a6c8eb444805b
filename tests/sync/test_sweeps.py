"""The sweeps check: (window, tail, knot) triples in seconds, on the 10 ms tick, named for the block."""

import pytest

from cogblocks.sync.sweeps import WHOLE_TRIAL_SWEEPS, checked_sweeps


class Owner:
    pass


def test_good_sweeps_come_back_as_float_triples():
    assert checked_sweeps(Owner(), [(4, 4, 0.25)]) == ((4.0, 4.0, 0.25),)
    assert checked_sweeps(Owner(), WHOLE_TRIAL_SWEEPS) == WHOLE_TRIAL_SWEEPS


@pytest.mark.parametrize(
    ("sweeps", "message"),
    [
        ([(4.0, 4.0, 0.3)], "knot divide window"),
        ([(4.0, 4.005, 0.25)], "multiples of 0.01 s"),
        ([(4.0, -1.0, 0.25)], "tail >= 0"),
        ([(0.0, 4.0, 0.25)], "window and knot"),
        ([(4.0, 4.0)], "triples"),
        (5, "triples"),
    ],
)
def test_a_bad_sweep_is_refused_naming_the_block(sweeps, message):
    with pytest.raises(ValueError, match=rf"^Owner: .*{message}"):
        checked_sweeps(Owner(), sweeps)
