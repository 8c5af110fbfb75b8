"""The object library: ready modal models of everyday objects, with their sizes and named,
described strike points. Every file is one of the shipped models (``patches.shipped`` builds
them from formulas or from a mesh through ``jassy modes``); ``jassy list --objects`` prints
this table and ``jassy doc MODEL`` a model's points with these descriptions.
"""

from __future__ import annotations

from typing import NamedTuple


class ObjectInfo(NamedTuple):
    file: str  # model file beside the built-in patches
    size: str  # real dimensions
    description: str  # material, how it is held, how its model was made
    points: dict[str, str]  # strike point -> where it is


def _along(name: str, count: int, what: str) -> dict[str, str]:
    return {f"{name}{i}": f"{what} {i}/{count - 1} of the way" for i in range(count)}


def _along_track(between: int, what: str) -> dict[str, str]:
    """t0 .. t8 and the ``between`` points in each interval (patches.models_surface.track_points)."""
    from patches.models_surface import track_points

    fractions, names = track_points(9, between)
    return {name: f"{what} {w:.1%} of the way" for name, w in zip(names, fractions, strict=True)}


OBJECTS: dict[str, ObjectInfo] = {
    "bell": ObjectInfo(
        "bell_model.toml", "church bell, strike note 392 Hz (about 0.5 m across)",
        "bronze bell, 120 partials as split doublets (beating), formula model",
        {"lip": "the rim", "soundbow": "the thick band just above the lip, where clappers strike",
         "waist": "half way up the side", "shoulder": "the upper curve", "crown": "the top"},
    ),
    "bowl": ObjectInfo(
        "bowl_model.toml", "bronze bowl, 140 mm across, 55 mm high, 5 mm wall",
        "finite elements (jassy modes) of a slightly out-of-round bowl: split doublets",
        {"rim": "just below the rim on the major axis", "rim45": "just below the rim, 45 degrees round",
         "wall": "half way up the outside", "base": "the centre of the bottom, outside",
         "inside": "the centre of the bottom, inside"},
    ),
    "metal_bar": ObjectInfo(
        "bar_model.toml", "aluminium bar, 217 mm long, 8 mm thick", "free-free Euler-Bernoulli bar, 5 modes",
        _along("x", 9, "along the bar from one end:"),
    ),
    "glass_plate": ObjectInfo(
        "glass_plate_model.toml", "soda-lime glass plate, 300 x 200 x 5 mm",
        "simply supported Kirchhoff plate, modes to 20 kHz; any point: {surface = [u, v]}",
        {"centre": "the middle", "off_centre": "41 % across, 37 % up", "near_edge": "13 % across, 29 % up",
         "corner": "7 % from each edge of a corner"},
    ),
    "steel_plate": ObjectInfo(
        "steel_plate_model.toml", "steel plate, 600 x 450 x 2 mm",
        "simply supported plate, 675 modes to 16 kHz; any point: {surface = [u, v]}",
        _along_track(7, "on the diagonal track from (12 %, 30 %) to (88 %, 62 %):"),
    ),
    "wooden_board": ObjectInfo(
        "wood_board_model.toml", "pine board, 800 x 300 x 18 mm",
        "orthotropic simply supported plate; any point: {surface = [u, v]}",
        _along_track(3, "on the track from (10 %, 50 %) to (90 %, 40 %):"),
    ),
    "tin_sheet": ObjectInfo(
        "tin_sheet_model.toml", "tinplate panel, 500 x 350 x 0.8 mm",
        "steel sheet nailed to a frame (simply supported), 1106 modes to 16 kHz; "
        "any point: {surface = [u, v]}",
        {f"x{i}y{j}": f"grid point {(i + 0.5) / 4:.0%} across, {(j + 0.5) / 3:.0%} up"
         for i in range(4) for j in range(3)},
    ),
    "door": ObjectInfo(
        "door_model.toml", "solid pine door, 0.8 x 2.0 m, 40 mm thick",
        "closed in its frame (simply supported edges), grain vertical, 399 modes to 16 kHz; "
        "any point: {surface = [u, v]}",
        {"centre": "the middle", "upper_panel": "centre line, 1.5 m up",
         "lower_panel": "centre line, 0.5 m up", "latch_edge": "beside the handle, 0.95 m up",
         "hinge_edge": "6 cm from the hinges, 1 m up"},
    ),
    "wine_glass": ObjectInfo(
        "wine_glass_model.toml",
        "soda-lime wine glass, 155 mm tall, bowl 76 mm across (62 mm at the rim), 2.2 mm wall, "
        "70 mm stem on a 64 mm foot",
        "finite elements (jassy modes) of a revolved profile, free (held lightly), 24 modes to 13 kHz "
        "(degenerate pairs kept apart); "
        "reference gain stored",
        {"rim": "3 mm below the rim, outside", "bowl": "the widest point of the bowl",
         "stem": "half way up the stem", "foot": "the edge of the foot"},
    ),
    "mug": ObjectInfo(
        "mug_model.toml",
        "ceramic mug, 82 mm across, 95 mm tall, 4 mm wall, 6 mm base, D-shaped handle of 10 mm "
        "round section",
        "finite elements (jassy modes) of the revolved cup with its handle, free, 24 modes to 19 kHz; "
        "reference gain stored",
        {"rim": "3 mm below the rim, a quarter turn from the handle",
         "side": "half way up the side, a quarter turn from the handle",
         "handle": "the outside of the handle's bend", "base": "the centre of the bottom, outside"},
    ),
    "pot": ObjectInfo(
        "pot_model.toml",
        "cast-iron cooking pot (a Dutch oven without its lid), 254 mm across, 127 mm tall, 5 mm wall, "
        "6 mm base",
        "finite elements (jassy modes) of the revolved pot, grey cast iron (E 103 GPa, 7300 kg/m^3, "
        "loss factor 0.01), free (standing on a cloth), 30 modes, 228 Hz to 3.1 kHz; reference gain stored",
        {"rim": "3 mm below the rim, outside", "wall": "half way up the outside",
         "base": "the centre of the bottom, outside", "inside": "the centre of the bottom, inside"},
    ),
}  # fmt: skip


def object_for_model(name: str) -> ObjectInfo | None:
    """The library entry whose model file holds the model called ``name`` (by file stem)."""
    for info in OBJECTS.values():
        if info.file.removesuffix("_model.toml") == name or info.file.removesuffix(".toml") == name:
            return info
    return None
