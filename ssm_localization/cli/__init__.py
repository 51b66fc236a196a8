"""
The ``ssm_localization`` command line: ``main.py`` (parser, ``main``), one module per command.

Nothing is imported here, so that a library module may use the argument types of
``arguments.py`` without loading every subcommand (and, through them, itself).
"""
