"""The current user's registry keys (``HKEY_CURRENT_USER``), behind one small interface.

On Windows :class:`WindowsUserRegistry` reads and writes the real registry through
``winreg``; no administrator is needed, the keys are the user's own. :class:`FileUserRegistry`
keeps the same keys in a JSON file (``{"Software\\\\Classes\\\\x": {"": "value"}}``): to see
what would be written, and to test the code that writes them on any system. Keys are paths
below ``HKEY_CURRENT_USER`` with ``\\`` between their parts; a value's name ``""`` is the
key's default value. Only string values (``REG_SZ``) are used. Every method runs in the
caller's thread.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Protocol

from phantomtouch.errors import DeviceError


class UserRegistry(Protocol):
    """String values of the current user's registry keys."""

    def get(self, key: str, name: str = "") -> str | None:
        """The string value ``name`` of ``key`` (``""``: its default), or None if either
        is missing."""
        ...

    def set(self, key: str, name: str, value: str) -> None:
        """Write the string value ``name`` of ``key``, creating the key and its parents."""
        ...

    def delete_tree(self, key: str) -> bool:
        """Remove ``key`` with its values and every key below it; False if it was missing."""
        ...


class FileUserRegistry:
    """The keys in a JSON file, written whole on each change (created when first written).

    Raises
    ------
    DeviceError
        The file cannot be read, is not such a JSON object, or cannot be written.
    """

    def __init__(self, path: Path) -> None:
        self.path = path

    def _load(self) -> dict[str, dict[str, str]]:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return {}
        except OSError as exc:
            raise DeviceError(f"cannot read the registry file {str(self.path)!r}: {exc}") from exc
        try:
            keys = json.loads(text)
        except ValueError as exc:
            raise DeviceError(f"the registry file {str(self.path)!r} is not JSON: {exc}") from exc
        if not isinstance(keys, dict) or not all(
            isinstance(values, dict) and all(isinstance(v, str) for v in values.values())
            for values in keys.values()
        ):
            raise DeviceError(
                f"the registry file {str(self.path)!r} must map each key to its string values"
            )
        return keys

    def _save(self, keys: dict[str, dict[str, str]]) -> None:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_text(json.dumps(keys, indent=2, sort_keys=True), encoding="utf-8")
        except OSError as exc:
            raise DeviceError(f"cannot write the registry file {str(self.path)!r}: {exc}") from exc

    def get(self, key: str, name: str = "") -> str | None:
        return self._load().get(_folded(key), {}).get(name)

    def set(self, key: str, name: str, value: str) -> None:
        keys = self._load()
        parts = _folded(key).split("\\")
        for depth in range(1, len(parts)):  # the parents exist, as in the registry
            keys.setdefault("\\".join(parts[:depth]), {})
        keys.setdefault(_folded(key), {})[name] = value
        self._save(keys)

    def delete_tree(self, key: str) -> bool:
        keys = self._load()
        top = _folded(key)
        doomed = [k for k in keys if k == top or k.startswith(top + "\\")]
        for k in doomed:
            del keys[k]
        if doomed:
            self._save(keys)
        return bool(doomed)


def _folded(key: str) -> str:
    """A key's path as the file keeps it: lower case (the registry ignores case), ``\\``
    between non-empty parts."""
    return "\\".join(part for part in key.replace("/", "\\").lower().split("\\") if part)


if sys.platform == "win32":
    import winreg

    class WindowsUserRegistry:
        """The real registry, ``HKEY_CURRENT_USER`` (Windows only).

        Raises
        ------
        DeviceError
            The registry refused a read or a write (the message says which key).
        """

        def get(self, key: str, name: str = "") -> str | None:
            try:
                with winreg.OpenKey(winreg.HKEY_CURRENT_USER, key) as handle:
                    value, kind = winreg.QueryValueEx(handle, name)
            except FileNotFoundError:
                return None
            except OSError as exc:
                raise DeviceError(f"cannot read HKEY_CURRENT_USER\\{key}: {exc}") from exc
            return value if kind in (winreg.REG_SZ, winreg.REG_EXPAND_SZ) else None

        def set(self, key: str, name: str, value: str) -> None:
            try:
                with winreg.CreateKeyEx(winreg.HKEY_CURRENT_USER, key) as handle:
                    winreg.SetValueEx(handle, name, 0, winreg.REG_SZ, value)
            except OSError as exc:
                raise DeviceError(f"cannot write HKEY_CURRENT_USER\\{key}: {exc}") from exc

        def delete_tree(self, key: str) -> bool:
            try:
                with winreg.OpenKey(
                    winreg.HKEY_CURRENT_USER, key, 0, winreg.KEY_READ | winreg.KEY_WRITE
                ) as handle:
                    while True:  # winreg deletes only keys without subkeys: children first
                        try:
                            child = winreg.EnumKey(handle, 0)
                        except OSError:
                            break
                        self.delete_tree(f"{key}\\{child}")
                winreg.DeleteKey(winreg.HKEY_CURRENT_USER, key)
            except FileNotFoundError:
                return False
            except OSError as exc:
                raise DeviceError(f"cannot remove HKEY_CURRENT_USER\\{key}: {exc}") from exc
            return True


def user_registry(path: Path | None = None) -> UserRegistry:
    """The file stand-in at ``path``, or (None) the real registry on Windows.

    Raises
    ------
    DeviceError
        ``path`` is None and this is not Windows.
    """
    if path is not None:
        return FileUserRegistry(path)
    if sys.platform == "win32":
        return WindowsUserRegistry()
    raise DeviceError(
        "the Windows registry exists only on Windows; give --registry FILE to write the same "
        "keys to a file"
    )
