"""Optional dependencies: one place that maps each extra to the modules it brings and turns a
missing one into an error that says what to install.

Modules that need an optional dependency import it inside ``with requires_extra("X"):``;
``tests/test_dependencies.py`` checks that every third-party import of the package is either a
core dependency or sits in such a block naming an extra of pyproject.toml that provides it.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from selfplaydrive.errors import MissingExtraError

# torch is not an extra on purpose: a bare `torch` requirement pulls the CUDA build (gigabytes)
TORCH_HINT = (
    "install the CPU build of PyTorch first: `pip install torch==2.13.0` where a CPU wheel is "
    "configured locally, otherwise `pip install torch --index-url https://download.pytorch.org/whl/cpu`"
)


@contextmanager
def requires_extra(extra: str) -> Iterator[None]:
    """Turn an ImportError of the block into a `MissingExtraError` naming what to install.

    Args:
        extra: The optional-dependency group of pyproject.toml (e.g. ``"sb3"``), or ``"torch"``.

    Raises:
        MissingExtraError: When an import inside the block fails.
    """
    try:
        yield
    except ImportError as exc:
        if isinstance(exc, MissingExtraError):
            raise
        missing = exc.name or str(exc)
        if extra == "torch":
            hint = TORCH_HINT
        else:
            hint = f"install it with `pip install 'selfplaydrive[{extra}]'` (or `selfplaydrive[all]`)"
        raise MissingExtraError(f"this feature needs the optional module {missing!r}; {hint}") from exc
