"""Names that print alike but differ are explained, not just called unknown."""

import pytest

from ibik_pin.names import normalized, unknown_names_message, why_unknown

KNOWN = ["Hip", "RKnee", "LKnee", "RShoulder"]


def test_a_cyrillic_letter_that_looks_latin_is_named_with_its_code_point():
    reason = why_unknown("RKn\u0435e", KNOWN)
    assert reason == ("'RKn\u0435e' is not 'RKnee': character 4 is '\u0435' (CYRILLIC SMALL LETTER IE, U+0435), "
                      "not 'e' (LATIN SMALL LETTER E, U+0065)")


@pytest.mark.parametrize(("name", "reason"), [
    ("rknee", "'rknee' differs from 'RKnee' in case only"),
    ("RShoulderr", "the nearest known name is 'RShoulder'"),
    ("Zygote", ""),
])
def test_other_near_misses_say_what_differs(name, reason):
    assert why_unknown(name, KNOWN) == reason


def test_decomposed_accents_and_surrounding_spaces_normalise_to_the_composed_name():
    assert normalized(" Cre\u0300me\t") == "Cr\u00e8me"
    assert "is known once normalised" in why_unknown("Cre\u0300me", ["Cr\u00e8me"])


def test_the_message_lists_every_unknown_name_with_its_reason_where_there_is_one():
    assert unknown_names_message(["rknee", "Zygote"], KNOWN) == (
        "rknee ('rknee' differs from 'RKnee' in case only), Zygote")
