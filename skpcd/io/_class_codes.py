"""LAS classification codes of class names: ASPRS codes where they exist,
user codes from 64 otherwise.

:func:`classification_codes` is the class -> code map with which
:func:`~skpcd.io.write_labelled_scan` writes predicted classes into the
``classification`` dimension of a LAS/LAZ file.
"""

import re

__all__ = [
    "ASPRS_CODES",
    "ASPRS_NAMES",
    "SKPCD_USER_CODES",
    "class_key",
    "classification_codes",
]

#: ASPRS standard classes (LAS 1.4 R15, point formats 6 to 10) by name
ASPRS_NAMES = {
    0: "never classified",
    1: "unclassified",
    2: "ground",
    3: "low vegetation",
    4: "medium vegetation",
    5: "high vegetation",
    6: "building",
    7: "low point (noise)",
    8: "reserved",
    9: "water",
    10: "rail",
    11: "road surface",
    12: "reserved",
    13: "wire - guard",
    14: "wire - conductor",
    15: "transmission tower",
    16: "wire - connector",
    17: "bridge deck",
    18: "high noise",
}

#: class names (lower case, words joined by ``_``) that have an ASPRS code
ASPRS_CODES = {
    "unknown": 1,
    "unclassified": 1,
    "ground": 2,
    "low_vegetation": 3,
    "medium_vegetation": 4,
    "bush": 4,
    "shrub": 4,
    "high_vegetation": 5,
    "vegetation": 5,
    "tree": 5,
    "building": 6,
    "buildings": 6,
    "facade": 6,
    "noise": 7,
    "low_noise": 7,
    "water": 9,
    "rail": 10,
    "road": 11,
    "road_surface": 11,
    "wire_guard": 13,
    "wire": 14,
    "wires": 14,
    "power_line": 14,
    "power_lines": 14,
    "wire_conductor": 14,
    "transmission_tower": 15,
    "tower": 15,
    "wire_connector": 16,
    "bridge": 17,
    "bridge_deck": 17,
    "high_noise": 18,
}

#: the user codes (64 on) of skpcd's own class names, in a fixed order so
#: that a class keeps its code whatever the model's other classes
SKPCD_USER_CODES = {
    name: 64 + k
    for k, name in enumerate(
        (
            "car",
            "pole",
            "lamp_post",
            "street_light",
            "street_lamp",
            "traffic_light",
            "pedestrian_signal",
            "traffic_sign",
            "fence",
            "person",
            "other",
            "truck",
        )
    )
}
_FIRST_FREE = 64 + len(SKPCD_USER_CODES)


def class_key(name):
    """A class name as looked up: lower case, words joined by ``_``."""
    return re.sub(r"[\s\-]+", "_", str(name).strip().lower())


def classification_codes(class_names, codes=None):
    """The LAS classification code of each class name.

    ASPRS codes where the name is an ASPRS class (``ground`` 2, ``bush`` and
    ``medium_vegetation`` 4, ``tree``, ``vegetation`` and
    ``high_vegetation`` 5, ``building`` and ``facade`` 6, ``noise`` 7,
    ``water`` 9, ``rail`` 10, ``road`` 11, ``wire_guard`` 13, ``wire`` 14,
    ``transmission_tower`` 15, ``bridge`` 17, ``unknown`` 1: unclassified);
    skpcd's own class names (``car``, ``pole``, ``traffic_sign``...) the
    fixed user codes of :data:`SKPCD_USER_CODES` (64 on); any other name the
    next free user code, in the order of ``class_names``. Names are matched
    in lower case, spaces and hyphens read as ``_``.

    Parameters
    ----------
    class_names : sequence of str
        The class names.
    codes : dict of str to int, default=None
        Codes given for some names (0 to 255), in place of the above.

    Returns
    -------
    codes : list of int
        The code of ``class_names[j]`` at ``j``.

    Raises
    ------
    ValueError
        If a given code is not 0 to 255, or more names need a user code
        than 64 to 255 holds.

    Examples
    --------
    >>> from skpcd.io._class_codes import classification_codes
    >>> classification_codes(["building", "car", "kiosk", "tree", "wire"])
    [6, 64, 76, 5, 14]
    """
    given = {class_key(k): v for k, v in (codes or {}).items()}
    for name, code in given.items():
        if not isinstance(code, int) or not 0 <= code <= 255:
            raise ValueError(f"the code of class {name!r} must be 0 to 255, got {code}")
    fixed = {**ASPRS_CODES, **SKPCD_USER_CODES, **given}
    taken = set(fixed.values())
    out, new = [], {}
    free = _FIRST_FREE
    for name in class_names:
        key = class_key(name)
        if key in fixed:
            out.append(fixed[key])
            continue
        if key not in new:
            while free in taken:
                free += 1
            if free > 255:
                raise ValueError(
                    f"class {name!r}: no user classification code left (64 to 255)"
                )
            new[key] = free
            taken.add(free)
        out.append(new[key])
    return out
