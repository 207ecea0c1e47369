"""The library's docstring examples run with the tests (``--doctest-modules`` over zmap and
cad_io, pyproject.toml). Those of the cam and access modules go to the xdist worker of their
tests' group, which compiles those kernels once for both (tests/conftest.py says why)."""

from __future__ import annotations

import pytest

#: doctest node ids by path prefix, and the xdist group of the tests of the same kernels
_GROUPS = (("zmap/cam/", "cam"), ("zmap/access/", "access"), ("cad_io/access", "access"))


@pytest.hookimpl(tryfirst=True)  # before xdist names the items by their group
def pytest_collection_modifyitems(config, items) -> None:
    for item in items:
        for prefix, group in _GROUPS:
            if item.nodeid.startswith(prefix):
                item.add_marker(pytest.mark.xdist_group(group))
