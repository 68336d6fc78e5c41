"""Names users type (markers, keypoints, cameras): compared after Unicode normalisation, and an
unknown one explained by what makes it differ from the nearest known name.

Two names that print alike can differ: an accent composed (one code point) or decomposed (a letter
and a combining mark), a Cyrillic or Greek letter that looks Latin, a non-breaking space, another
case. NFC normalisation makes the first kind equal; the others are named in the message, with
each differing character's Unicode name, so the user sees what no font shows.
"""

from __future__ import annotations

import difflib
import unicodedata
from collections.abc import Iterable, Sequence

__all__ = ["normalized", "unknown_names_message", "why_unknown"]


def normalized(name: str) -> str:
    """The name as compared: NFC (composed accents), surrounding white space removed."""
    return unicodedata.normalize("NFC", name).strip()


def _character(character: str) -> str:
    return f"{character!r} ({unicodedata.name(character, 'unnamed')}, U+{ord(character):04X})"


def why_unknown(name: str, known: Sequence[str]) -> str:
    """Why `name` matches none of `known`, in a phrase: the nearest known name and what differs
    (case, or the characters that look alike but are others); "" when no known name is near."""
    name = normalized(name)
    if name in known:
        return f"{name!r} is known once normalised (NFC: composed accents)"
    folded = {candidate.casefold(): candidate for candidate in known}
    if name.casefold() in folded:
        return f"{name!r} differs from {folded[name.casefold()]!r} in case only"
    nearest = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    if not nearest:
        return ""
    closest = nearest[0]
    if len(closest) == len(name):
        differences = [f"character {index + 1} is {_character(mine)}, not {_character(theirs)}"
                       for index, (mine, theirs) in enumerate(zip(name, closest, strict=True)) if mine != theirs]
        if len(differences) <= 3:
            return f"{name!r} is not {closest!r}: " + "; ".join(differences)
    return f"the nearest known name is {closest!r}"


def unknown_names_message(unknown: Iterable[str], known: Sequence[str]) -> str:
    """The unknown names, each with `why_unknown` where it finds a near known name."""
    parts = []
    for name in unknown:
        reason = why_unknown(name, known)
        parts.append(f"{name} ({reason})" if reason else name)
    return ", ".join(parts)
