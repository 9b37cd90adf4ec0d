"""The built-in scenes' names, importable without the modules that make them: a command's
``--help`` names them without loading scikit-image or the ray caster
(``tests/vbgs/data/test_scene_names.py`` holds them to :data:`vbgs.data.synthetic.SCENES`
and :data:`vbgs.data.stereo.REAL_SCENES`)."""

SYNTHETIC = ("object", "room", "walk", "walk-long", "object-change", "room-change",
             "walk-change")
REAL = ("motorcycle",)  # real frames loadable by name
