"""Tests of ibik_pin.app.options: the library's errors reworded with the command's options."""

import pytest

from ibik_pin.app.options import as_options
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.vision.camera import select_cameras


def test_an_error_about_a_mapped_parameter_names_the_option_and_keeps_its_type():
    expected = r"^--cameras: unknown camera name\(s\) \['z'\]"
    with pytest.raises(UnknownNameError, match=expected) as raised, as_options({"names": "--cameras"}):
        select_cameras([], ["z"])
    assert raised.value.parameter == "names"
    assert str(raised.value.__cause__).startswith("names: unknown camera name")


def test_an_error_about_another_parameter_passes_unchanged():
    with pytest.raises(InputError, match=r"^frames: no frame$"), as_options({"names": "--cameras"}):
        raise InputError("frames: no frame", parameter="frames")
