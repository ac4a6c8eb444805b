"""forwarding: an old module path gives the new module's names with a warning that names the new path."""

import warnings

import pytest

from cogblocks.sim.moved import forwarding


def test_a_forwarded_name_is_the_new_modules_object_and_the_warning_names_the_new_path():
    forward = forwarding("old.place", "cogblocks.sim.timing")
    with pytest.warns(DeprecationWarning, match=r"old\.place moved to cogblocks\.sim\.timing; import BASE_STEP"):
        step = forward("BASE_STEP")
    from cogblocks.sim.timing import BASE_STEP

    assert step == BASE_STEP


@pytest.mark.parametrize("name", ["nope", "__path__"])
def test_a_name_the_new_module_lacks_or_a_dunder_is_an_attribute_error_naming_the_old_path(name):
    forward = forwarding("old.place", "cogblocks.sim.timing")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError, match=rf"module 'old.place' has no attribute '{name}'"):
            forward(name)
