"""The position-domain breakdown of the avatar's peak speed (studies/position_naturalness.py)."""

import numpy as np
import pytest

from cogblocks.diagrams.sync import run_sync
from studies.position_naturalness import breakdown, main, peak_speed_ratio


def test_the_peak_speed_ratio_of_two_sampled_cosines_is_their_frequency_ratio():
    t = np.arange(0.0, 20.0, 0.01)
    person, avatar = np.cos(2.0 * t), np.cos(3.0 * t)
    # the largest change per tick of cos(ωt) is ω·dt to first order
    assert peak_speed_ratio(avatar, person, 0) == pytest.approx(1.5, rel=1e-3)
    assert peak_speed_ratio(avatar, person, 1000) == pytest.approx(1.5, rel=1e-3)


def test_the_whole_trial_avatar_ratio_is_the_naturalness_figure_of_run_sync():
    [whole, late] = breakdown(1, [0, 300])
    row = run_sync(1, ["mean"], "position", progress=False)["results"][0]
    assert whole["avatar"] == pytest.approx(row["position_peak_speed_ratio"], rel=1e-12)
    assert whole["change_pct"] == pytest.approx(row["change_pct"], rel=1e-9)  # r summed in another order
    # the estimator's first seconds dominate the whole trial's figure, for the estimate alone too
    assert whole["estimate_alone"] > 5 * late["estimate_alone"]
    assert late["avatar"] > late["estimate_alone"]


def test_the_command_prints_one_json_line_per_start(capsys):
    main(["--group", "1", "--from-tick", "0", "--from-tick", "500"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.count('"from_tick"') for line in lines] == [1, 1]
    assert '"from_tick": 500' in lines[1]
