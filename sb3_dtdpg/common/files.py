"""Writing output files safely: atomic replacement, JSON records, leftover temporary files, file names from user text."""

from __future__ import annotations

import json
import os
import re
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "TEMP_PREFIX",
    "atomic_write",
    "json_default",
    "remove_temp_files",
    "safe_name",
    "save_figure",
    "write_csv",
    "write_json",
    "write_text",
]

#: Temporary files are named ``.<target>.<random>.tmp`` in the target's folder.
TEMP_PREFIX = "."
_TEMP_SUFFIX = ".tmp"


def _new_file_mode() -> int:
    """The mode ``open(path, "w")`` gives a new file: 0666 less the process's umask (read without changing it)."""
    try:  # Linux: the umask is in /proc, so no other thread sees it change
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path: str | os.PathLike[str], write: Callable[[str], None]) -> Path:
    """
    Write a file so that a reader sees either the old file or the complete new one, never a part.

    ``write`` gets the path of a temporary file in the same folder (so that ``os.replace`` is an atomic
    rename), which then replaces ``path``. On any error, including ``KeyboardInterrupt``, the temporary file is
    removed; a process killed outright (SIGKILL, power loss) may leave one, which :func:`remove_temp_files`
    removes later.

    :param path: the target file
    :param write: writes the content to the path it is given (e.g. ``model.save``); the path ends in ``.tmp``,
        so SB3's ``save`` keeps it as it is
    :return: the target path
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}{path.name}.", suffix=_TEMP_SUFFIX, dir=path.parent)
    os.close(fd)
    os.chmod(tmp, _new_file_mode())  # mkstemp makes the file private (0600); open() would give 0666 less the umask
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def json_default(value: Any) -> Any:
    """
    ``json.dumps``'s ``default`` for numpy values: scalars become Python numbers, arrays lists.

    :param value: a value ``json`` cannot write
    :return: its JSON-ready form
    :raises TypeError: for anything else
    """
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_json(path: str | os.PathLike[str], data: Any, indent: int | None = None, strict: bool = False) -> Path:
    """
    Write a JSON file atomically (:func:`atomic_write`): a reader sees the complete record or the previous one.

    :param path: the target file
    :param data: the record (numpy values allowed, :func:`json_default`)
    :param indent: ``json.dumps``'s indent
    :param strict: write non-finite numbers as ``null`` (JSON has no NaN; strict readers refuse Python's ``NaN``)
    :return: the target path
    """
    if strict:
        return write_text(path, json.dumps(_finite(data), indent=indent, default=json_default, allow_nan=False))
    return write_text(path, json.dumps(data, indent=indent, default=json_default))


def _finite(value: Any) -> Any:
    """:return: ``value`` with every non-finite number (also in numpy arrays) replaced by None"""
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_finite(item) for item in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    return value


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """
    Write a text file atomically (:func:`atomic_write`).

    :param path: the target file
    :param text: its content
    :return: the target path
    """
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))


def write_csv(path: str | os.PathLike[str], frame: Any) -> Path:
    """
    Write a table as CSV, without its index, atomically (:func:`atomic_write`).

    :param path: the target file
    :param frame: a ``pandas.DataFrame``
    :return: the target path
    """
    return atomic_write(path, lambda tmp: frame.to_csv(tmp, index=False))


def save_figure(figure: Any, path: str | os.PathLike[str], **kwargs: Any) -> Path:
    """
    Save a matplotlib figure atomically (:func:`atomic_write`), in the format its file extension names.

    :param figure: the figure
    :param path: the target file (``.png``, ``.pdf``, ``.svg``, ...)
    :param kwargs: ``Figure.savefig``'s options (e.g. ``dpi``)
    :return: the target path
    """
    file_format = Path(path).suffix.lstrip(".").lower() or None  # the temporary file ends in .tmp
    return atomic_write(path, lambda tmp: figure.savefig(tmp, format=file_format, **kwargs))


def remove_temp_files(folder: str | os.PathLike[str], names: Iterable[str] | None = None) -> list[Path]:
    """
    Remove the temporary files that :func:`atomic_write` left in a folder (not recursive) when a process was killed.

    :param folder: the folder (missing: nothing to do)
    :param names: only those of writes to these file names (None: any; for a folder that only this program writes,
        as a user's folder may hold other programs' hidden ``.tmp`` files, or another job's writes in progress)
    :return: the removed files
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    prefixes = (TEMP_PREFIX,) if names is None else tuple(f"{TEMP_PREFIX}{name}." for name in names)
    removed = []
    for entry in folder.iterdir():
        if entry.name.startswith(prefixes) and entry.name.endswith(_TEMP_SUFFIX) and entry.is_file():
            entry.unlink(missing_ok=True)
            removed.append(entry)
    return removed


_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def safe_name(text: str, max_chars: int = 80) -> str:
    """
    A file-name component made from user text (e.g. a scenario name): separators, ``..``, control and other
    special characters become ``_``, so the result never leaves the folder it is joined to.

    :param text: the text
    :param max_chars: longest result
    :return: a non-empty name of letters, digits and ``._+-``, not starting with a dot
    """
    name = re.sub(r"_+", "_", _UNSAFE.sub("_", text).replace("..", "_")).lstrip(".")[:max_chars]
    return name or "_"


def unused_path(folder: str | os.PathLike[str], stem: str, suffix: str) -> Path:
    """
    A path in ``folder`` that no file holds yet: ``<stem><suffix>``, else ``<stem>_2<suffix>``, ``<stem>_3<suffix>``, ...
    (so that a second save of the same kind keeps the first).

    :param folder: the folder
    :param stem: the file name without its suffix
    :param suffix: the suffix, with its dot (``.zip``)
    :return: the first free path
    """
    folder = Path(folder)
    path, number = folder / f"{stem}{suffix}", 1
    while path.exists():
        number += 1
        path = folder / f"{stem}_{number}{suffix}"
    return path
