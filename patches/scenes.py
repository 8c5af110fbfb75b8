"""The built-in scenes: physics runs first, then its contacts drive the sound.

A scene is a module of this package with a render function
``render(out, haptic_path, csv_path, duration, sample_rate, block, **options)``; adding one is
that module and one line here (``jassy render``, ``jassy list`` and ``jassy check-audio`` read
this table, importing a scene's module only when it is used).
"""

#: Scene name -> (module, render function).
SCENES = {
    "drill": ("patches.drill", "render_drill"),
    "wok": ("patches.wok", "render_wok"),
    "drop": ("patches.drop", "render_drop"),
    "poke": ("patches.poke", "render_poke"),
    "archery": ("patches.archery", "render_archery"),
}
