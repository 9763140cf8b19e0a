"""Mesh file formats: one reader module per format (its docstring says what of
the format is read), over ``part`` (what a reader hands back, failures, file
reading) and ``text`` (parsing shared by the text formats).

:data:`clrt.scene.load.READERS` registers each reader with its extensions;
nothing here imports :mod:`clrt.scene.load`.
"""
