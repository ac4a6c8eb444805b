"""The planner's profile (studies/planner_profile.py): decisions recorded, time attributed to the planner."""

from studies.planner_profile import main, profile


def test_the_profile_sees_every_decision_inside_the_planners_update():
    decide_ms, stats = profile(duration=20.0, seconds=1.5)
    assert len(decide_ms) == 2 and min(decide_ms) > 0.0  # the first decision, then one a second later
    updates = [v for (path, _, name), v in stats.stats.items() if path.endswith("receding.py") and name == "update"]
    assert len(updates) == 1 and updates[0][0] == 151  # called once a tick


def test_the_command_prints_the_decisions_and_both_orderings(capsys):
    main(["--duration", "20", "--seconds", "0.5", "--top", "3"])
    out = capsys.readouterr().out
    assert out.startswith("decide_ms: ")
    assert "Ordered by: internal time" in out and "Ordered by: cumulative time" in out
