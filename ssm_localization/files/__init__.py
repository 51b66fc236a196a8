"""
User files read and written with guards: the bottom layer, imported by every other one.

- ``reading.py``: input files must be readable regular files of bounded size; echoes of their
  content in error messages are clipped;
- ``yaml_input.py``: YAML through a ``yaml.SafeLoader`` subclass that refuses alias bombs;
- ``writing.py``: output paths checked before any work, written atomically, nothing left behind
  on failure.

Nothing here imports the rest of the package.
"""
