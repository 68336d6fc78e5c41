"""The library's errors in the command's terms: an InputError about an API parameter reworded with
the `ibik` option that gave its value, so that the one line on stderr names what the user typed."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping

from ibik_pin.exceptions import InputError

__all__ = ["as_options"]


@contextlib.contextmanager
def as_options(options: Mapping[str, str]) -> Iterator[None]:
    """Re-raise an InputError about a parameter in `options` (parameter name -> option, e.g.
    {"names": "--cameras"}) as the same error with the option in place of the parameter's name."""
    try:
        yield
    except InputError as error:
        parameter = error.parameter
        if parameter is None or parameter not in options or not str(error).startswith(parameter):
            raise
        raise type(error)(options[parameter] + str(error)[len(parameter):], parameter=parameter) from error
