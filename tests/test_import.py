"""What ``import phantomtouch`` loads: its names on first use, scipy never."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import phantomtouch as pt


def loaded_after(code: str) -> dict[str, bool]:
    """Run ``code`` in a fresh interpreter; which heavy packages it left loaded."""
    probe = (
        f"{code}\n"
        "import json, sys\n"
        "top = {m.split('.')[0] for m in sys.modules}\n"
        "print(json.dumps({p: p in top for p in ('numpy', 'pydantic', 'scipy')}))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True
    )
    loaded: dict[str, bool] = json.loads(result.stdout.splitlines()[-1])
    return loaded


def test_import_loads_neither_numpy_nor_pydantic_nor_scipy() -> None:
    assert loaded_after("import phantomtouch") == {
        "numpy": False,
        "pydantic": False,
        "scipy": False,
    }


def test_the_schema_validates_a_pattern_without_numpy() -> None:
    code = (
        "from phantomtouch import TouchPattern, DeviceProfile\n"
        "TouchPattern.model_validate({'path': {'kind': 'polyline', 'points_cm': [[0, 0]]},"
        " 'duration_s': 1.0})\n"
    )
    assert loaded_after(code) == {"numpy": False, "pydantic": True, "scipy": False}


def test_rendering_loads_numpy_and_no_scipy() -> None:
    code = "import phantomtouch as pt\npt.render(pt.preset('exp2/curved'))\n"
    assert loaded_after(code) == {"numpy": True, "pydantic": True, "scipy": False}


@pytest.mark.parametrize("name", pt.__all__)
def test_every_public_name_resolves_and_is_listed(name: str) -> None:
    assert getattr(pt, name) is not None
    assert name in dir(pt)


def test_an_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'renderr'"):
        _ = pt.renderr  # type: ignore[attr-defined]
