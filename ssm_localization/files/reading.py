"""
Reading user files with bounds.

Clear errors for what is not a readable regular file, a size limit on what is read, and clipped
echoes of the input in error messages.
"""
from __future__ import annotations

from pathlib import Path
import reprlib
from typing import Any

#: longest echo of user input (a value, a parser message) inside an error message
MAX_ECHO_CHARS = 200

_REPR = reprlib.Repr()
_REPR.maxlevel = 3
_REPR.maxstring = _REPR.maxother = 60
_REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = _REPR.maxset = 6


def clip(text: Any, limit: int = MAX_ECHO_CHARS) -> str:
    """
    ``str(text)`` on one line (white space folded), at most ``limit`` characters.

    Only the first ``4 * limit`` characters are looked at, so a huge text costs nothing more.
    """
    head = str(text)[:4 * limit]
    one = ' '.join(head.split())
    return one if len(one) <= limit else one[:limit - 3] + '...'


def echo(value: Any, limit: int = MAX_ECHO_CHARS) -> str:
    """
    Return a bounded ``repr`` of a user value.

    Depth and element counts are cut, then the text is clipped (:func:`clip`).
    """
    return clip(_REPR.repr(value), limit)


def input_file(path: str | Path, what: str) -> Path:
    """
    ``path`` after checking it names an existing regular file; errors name ``what``.

    Raises ``FileNotFoundError`` (``'{what} not found: {path}'``) or ``ValueError`` for a
    directory or anything else that is not a regular file (a FIFO or a device would block or
    never end).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f'{what} not found: {p}')
    if p.is_dir():
        raise ValueError(f'{what} {p}: is a directory, expected a file')
    if not p.is_file():
        raise ValueError(f'{what} {p}: not a regular file')
    return p


def read_bounded(path: str | Path, what: str, max_bytes: int) -> bytes:
    """
    Return the bytes of the regular file ``path``, refusing one larger than ``max_bytes``.

    Never reads more than ``max_bytes + 1`` bytes. Raises ``ValueError`` naming ``what`` and
    the file when it is too large or cannot be read (permissions, I/O error).
    """
    p = input_file(path, what)
    try:
        with open(p, 'rb') as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise ValueError(f'{what} {p}: cannot read ({exc.strerror or exc})') from None
    if len(data) > max_bytes:
        raise ValueError(f'{what} {p}: larger than {max_bytes} bytes, refusing to read it')
    return data
