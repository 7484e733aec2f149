"""Expert demonstrations made: recorded and screened (:mod:`.generate`), rendered into
observations (:mod:`.render`), summarised (:mod:`.stats`). What they are on disk, and reading
them, is :mod:`mani_skill_softvt.data` (the file formats, below the expert and the evaluation);
this package drives the expert and the DSR-wrapped env, so it sits above both. The command is
``python -m mani_skill_softvt.demos`` (:mod:`mani_skill_softvt.cli.demos`).
"""
