"""
Output files and directories written safely.

Paths are checked before any work (:func:`check_output_file`, :func:`check_output_dir`), so a
long computation never ends on an unwritable output. Writers then write to a temporary name
beside the target and rename it into place when everything is written (:func:`atomic_files`,
:func:`atomic_dir`): on any failure the temporary files, and the directories created for them,
are removed, and an existing output is left as it was.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
import secrets
import shutil
import tempfile
from typing import Iterable, Iterator


def _existing_ancestor(path: Path) -> Path:
    anc = path.parent
    while not anc.exists():
        if anc.is_symlink():
            raise ValueError(f'{anc} is a broken symbolic link')
        anc = anc.parent
    return anc


def _check_parent(path: Path, what: str) -> None:
    try:
        anc = _existing_ancestor(path)
    except ValueError as exc:
        raise ValueError(f'{what} {path}: {exc}') from None
    if not anc.is_dir():
        raise ValueError(f'{what} {path}: {anc} is not a directory')
    if not os.access(anc, os.W_OK | os.X_OK):
        raise ValueError(f'{what} {path}: cannot create files in {anc} (permission denied)')


def check_output_file(path: str | Path, what: str,
                      inputs: Iterable[str | Path | None] = ()) -> Path:
    """
    ``path`` after checking a file can be written there; errors name ``what``.

    Refused with ``ValueError``: an existing directory, an existing non-regular file (a device,
    a FIFO: it would be replaced), a path under a regular file, an unwritable directory, and one
    of the command's ``inputs`` or a file inside an input directory (a bag's ``metadata.yaml``):
    an output must not overwrite what is read.
    """
    p = Path(path)
    if p.is_dir():
        raise ValueError(f'{what} {p}: is a directory, expected a file name')
    if p.exists() and not p.is_file():
        raise ValueError(f'{what} {p}: exists and is not a regular file')
    _check_parent(p, what)
    target = p.resolve()
    for source in inputs:
        if source is None:
            continue
        src = Path(source).resolve()
        if target == src or src in target.parents:
            raise ValueError(f'{what} {p}: would overwrite the input {source}')
    return p


def check_output_dir(path: str | Path, what: str, overwrite: bool | None = None) -> Path:
    """
    ``path`` after checking a directory can be written there; errors name ``what``.

    ``overwrite=None``: the directory may exist already (a folder that receives files);
    ``False``: it must not exist (``FileExistsError`` otherwise); ``True``: an existing one will
    be replaced. A regular file in its place is refused unless ``overwrite`` is true.
    """
    p = Path(path)
    if p.exists() or p.is_symlink():
        if overwrite is False:
            raise FileExistsError(f'{what} exists already (use --force to overwrite): {p}')
        if overwrite is None and not p.is_dir():
            raise ValueError(f'{what} {p}: exists and is not a directory')
    _check_parent(p, what)
    return p


def _make_parents(path: Path, what: str) -> list[Path]:
    """Create the missing parents of ``path``; the ones created, outermost first."""
    missing = []
    anc = path.parent
    while not anc.exists():
        missing.append(anc)
        anc = anc.parent
    missing.reverse()
    try:
        for d in missing:
            d.mkdir()
    except OSError as exc:
        _remove_dirs(missing)
        raise ValueError(f'{what} {path}: cannot create {exc.filename} '
                         f'({exc.strerror or exc})') from None
    return missing


def _remove_dirs(dirs: list[Path]) -> None:
    for d in reversed(dirs):
        with contextlib.suppress(OSError):
            d.rmdir()


def temporary_name(path: Path) -> Path:
    """
    Return a hidden, unique name beside ``path`` that keeps its suffix.

    Writers pick the format from the suffix: ``.out.3f2a9c1e.tmp.png``.
    """
    return path.with_name(f'.{path.stem}.{secrets.token_hex(4)}.tmp{path.suffix}')


@contextlib.contextmanager
def atomic_files(*paths: str | Path, what: str = 'output file') -> Iterator[tuple[Path, ...]]:
    """
    Write several files all or nothing: yields one temporary path per target.

    The caller writes every temporary path; when the block ends normally they are renamed over
    their targets. When it raises, the temporary files and the directories created for them are
    removed and the targets are untouched; an ``OSError`` becomes a ``ValueError`` naming the
    targets.
    """
    targets = [check_output_file(p, what) for p in paths]
    if len({t.resolve() for t in targets}) != len(targets):
        raise ValueError(f'{what}: the same file is named twice: {", ".join(map(str, paths))}')
    created: list[Path] = []
    for t in targets:
        created += _make_parents(t, what)
    tmps = tuple(temporary_name(t) for t in targets)
    try:
        yield tmps
        for tmp, target in zip(tmps, targets):
            os.replace(tmp, target)
    except BaseException as exc:
        for tmp in tmps:
            with contextlib.suppress(OSError):
                tmp.unlink()
        _remove_dirs(created)
        if isinstance(exc, OSError):
            names = ', '.join(str(t) for t in targets)
            raise ValueError(f'{what} {names}: cannot write ({exc.strerror or exc})') from None
        raise


@contextlib.contextmanager
def atomic_dir(path: str | Path, what: str = 'output directory',
               overwrite: bool = False) -> Iterator[Path]:
    """
    Write a directory all or nothing.

    Yields a path, not yet existing, with the same name in a temporary directory beside ``path``.

    The caller creates and fills it; when the block ends normally it replaces ``path`` (an
    existing one only with ``overwrite``). When it raises, everything written is removed and an
    existing ``path`` is untouched; an ``OSError`` becomes a ``ValueError`` naming ``path``.
    """
    target = check_output_dir(path, what, overwrite)
    created = _make_parents(target, what)
    try:
        stage = Path(tempfile.mkdtemp(prefix=f'.{target.name}.', suffix='.tmp',
                                      dir=target.parent))
    except OSError as exc:
        _remove_dirs(created)
        raise ValueError(f'{what} {target}: cannot write ({exc.strerror or exc})') from None
    try:
        yield stage / target.name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        elif target.exists() or target.is_symlink():
            target.unlink()
        os.replace(stage / target.name, target)
    except BaseException as exc:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_dirs(created)
        if isinstance(exc, OSError):
            raise ValueError(f'{what} {target}: cannot write ({exc.strerror or exc})') from None
        raise
    shutil.rmtree(stage, ignore_errors=True)
