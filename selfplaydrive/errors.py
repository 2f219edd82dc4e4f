"""Exceptions raised by selfplaydrive, each naming what was wrong and what was expected."""

from __future__ import annotations


class MapError(ValueError):
    """A map file or map element is malformed.

    Args:
        message: What is wrong and what was expected.
        path: The file being read, if any.
        element: The id of the offending element (node, way, relation, road, lane ...), if any.
    """

    def __init__(self, message: str, path: object = None, element: object = None) -> None:
        self.path = None if path is None else str(path)
        self.element = None if element is None else str(element)
        where = []
        if self.path is not None:
            where.append(f"file {self.path}")
        if self.element is not None:
            where.append(f"element {self.element}")
        prefix = f"[{', '.join(where)}] " if where else ""
        super().__init__(prefix + message)


class ConfigError(ValueError):
    """A configuration key or value is invalid; the message lists the valid choices."""


class CheckpointError(ValueError):
    """A checkpoint file is missing, unreadable, foreign or does not match the env.

    Args:
        message: What is wrong and what was expected.
        path: The checkpoint file.
    """

    def __init__(self, message: str, path: object = None) -> None:
        self.path = None if path is None else str(path)
        super().__init__(f"[file {self.path}] {message}" if self.path is not None else message)


class MissingExtraError(ImportError):
    """An optional dependency is not installed; the message says what to install."""
