"""Write a device profile to the TOML or JSON file that ``DeviceProfile.load`` reads."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema.device import DeviceProfile

_PER_LINE = 6
"""Numbers per line of a long TOML array (FIR taps)."""


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        # A TOML basic string takes JSON's escapes except \uD83D\uDE00 pairs for characters
        # beyond the BMP (TOML wants \U0001F600 or the character itself) and wants DEL
        # escaped: write every character as it is, escape control characters and DEL.
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, list):
        items = [_value(v) for v in value]
        if len(items) <= _PER_LINE and not any(isinstance(v, list) for v in value):
            return "[" + ", ".join(items) + "]"
        lines = [", ".join(items[i : i + _PER_LINE]) for i in range(0, len(items), _PER_LINE)]
        return "[\n  " + ",\n  ".join(lines) + ",\n]"
    raise ParameterError(f"cannot write {type(value).__name__} value {value!r} to TOML")


def profile_toml(profile: DeviceProfile) -> str:
    """The profile as TOML: top-level keys, then tables, then ``[[actuators]]``."""
    data = profile.model_dump(mode="json", exclude_none=True)
    actuators = data.pop("actuators")
    tables = {k: v for k, v in data.items() if isinstance(v, dict)}
    lines = [f"{k} = {_value(v)}" for k, v in data.items() if k not in tables]
    for name, table in tables.items():
        lines += ["", f"[{name}]", *(f"{k} = {_value(v)}" for k, v in table.items())]
    for actuator in actuators:
        lines += ["", "[[actuators]]", *(f"{k} = {_value(v)}" for k, v in actuator.items())]
    return "\n".join(lines) + "\n"


def write_profile(profile: DeviceProfile, path: str | Path) -> None:
    """Write ``profile`` to ``path``: ``.toml`` as TOML, ``.json`` as JSON.

    Raises
    ------
    ParameterError
        Another file suffix.
    DeviceError
        The file cannot be written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".toml":
        text = profile_toml(profile)
    elif suffix == ".json":
        text = json.dumps(profile.model_dump(mode="json", exclude_none=True), indent=2) + "\n"
    else:
        raise ParameterError(f"profile file {str(path)!r} must end in .toml or .json")
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise DeviceError(f"cannot write device profile {str(path)!r}: {exc}") from exc
