"""The lessons' tests launch stacks as the package's tests do (python/tests/conftest.py)."""

import importlib.util
import pathlib

_spec = importlib.util.spec_from_file_location(
    "troupe_stacks", pathlib.Path(__file__).resolve().parents[2] / "python" / "tests" / "conftest.py")
_stacks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_stacks)
launch = _stacks.launch
