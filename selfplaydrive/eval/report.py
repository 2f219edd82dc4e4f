"""Write an evaluation result as JSON plus a markdown table (shared by every analysis).

A result is a flat or nested dict whose leaves are numbers, strings, or estimate dicts as written
by the `to_dict()` of `selfplaydrive.eval.stats` records (`Proportion`, `RateEstimate`,
`KmBetween`, `MeanEstimate`). The markdown table has one row per metric: value, 95 % interval and
numerator / denominator (docs/metrics.md "Aggregates"; reference/metrics.md section 9).

Example:
    >>> from selfplaydrive.eval.stats import proportion
    >>> rows = table_rows({"collision_rate": proportion(1, 4).to_dict(), "n": 4})
    >>> [r[0] for r in rows], rows[0][1]
    (['collision_rate', 'n'], '0.25')
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["format_number", "json_safe", "markdown_table", "table_rows", "write_report"]


def json_safe(obj: Any) -> Any:
    """Recursively convert to strict-JSON values: estimate records via `to_dict()`, NumPy
    scalars and arrays to Python numbers and lists, inf/NaN floats to "inf"/"-inf"/"nan"."""
    if hasattr(obj, "to_dict"):
        return json_safe(obj.to_dict())
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "tolist"):  # NumPy scalar or array
        return json_safe(obj.tolist())
    if isinstance(obj, bool) or obj is None or isinstance(obj, (int, str)):
        return obj
    if isinstance(obj, float):
        if math.isnan(obj):
            return "nan"
        if math.isinf(obj):
            return "inf" if obj > 0 else "-inf"
        return obj
    raise ValueError(f"report: cannot write a value of type {type(obj).__name__} ({obj!r}) as JSON")


def format_number(x: Any, digits: int = 4) -> str:
    """Short text of a number: `digits` significant digits, "inf"/"nan" kept, ints exact."""
    if isinstance(x, str):
        return x
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, int):
        return str(x)
    x = float(x)
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}g}"


def _num_den(est: Mapping[str, Any]) -> str:
    """Numerator / denominator text of an estimate dict (its kind decides the fields)."""
    if "numerator" in est and "denominator" in est:
        return f"{format_number(est['numerator'])} / {format_number(est['denominator'])}"
    if "incidents" in est and "km" in est:  # KmBetween: km (numerator) / incidents
        return f"{format_number(est['km'])} km / {format_number(est['incidents'])}"
    if "n" in est:
        return f"n = {format_number(est['n'])}"
    return ""


def _is_estimate(v: Any) -> bool:
    return isinstance(v, Mapping) and "value" in v and "lo" in v and "hi" in v


def table_rows(result: Mapping[str, Any], prefix: str = "") -> list[tuple[str, str, str, str]]:
    """Rows (metric, value, 95 % CI, numerator / denominator) of a result dict.

    Nested dicts that are not estimates are flattened with dotted names; lists are skipped
    (they are data, not metrics).
    """
    rows: list[tuple[str, str, str, str]] = []
    for key, v in json_safe(result).items():
        name = f"{prefix}{key}"
        if _is_estimate(v):
            ci = f"[{format_number(v['lo'])}, {format_number(v['hi'])}]"
            rows.append((name, format_number(v["value"]), ci, _num_den(v)))
        elif isinstance(v, Mapping):
            rows.extend(table_rows(v, prefix=f"{name}."))
        elif not isinstance(v, list):
            rows.append((name, format_number(v), "", ""))
    return rows


def markdown_table(result: Mapping[str, Any], title: str | None = None) -> str:
    """A markdown table, one row per metric (value, 95 % CI, numerator / denominator)."""
    lines = [f"## {title}", ""] if title else []
    lines += ["| metric | value | 95 % CI | numerator / denominator |", "|---|---|---|---|"]
    lines += [f"| {m} | {v} | {ci} | {nd} |" for m, v, ci, nd in table_rows(result)]
    return "\n".join(lines) + "\n"


def write_report(
    result: Mapping[str, Any], out_dir: str | Path, name: str, title: str | None = None
) -> dict[str, Path]:
    """Write `<out_dir>/<name>.json` (strict JSON) and `<out_dir>/<name>.md` (table).

    Args:
        result: The results dict (estimate records or their dicts as leaves).
        out_dir: Folder, created if missing.
        name: File stem.
        title: Heading of the markdown file (default: `name`).

    Returns:
        {"json": path, "markdown": path}.

    Raises:
        ValueError: A value that cannot be written as JSON, or an empty/unsafe name.
    """
    if not name or "/" in name or "\\" in name:
        raise ValueError(f"report name: expected a plain file stem, got {name!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = json_safe(result)
    paths = {"json": out / f"{name}.json", "markdown": out / f"{name}.md"}
    paths["json"].write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    paths["markdown"].write_text(markdown_table(data, title or name))
    return paths
