"""The suite's groups for pytest-xdist (tests/conftest.py): a test that shares a module-scoped
fixture is in its module's group, a test alone is in none, and under ``--dist loadgroup`` the
group is in the node id the scheduler groups by (``nodeid@group``), whatever the pytest."""

import pytest


@pytest.fixture(scope="module")
def shared() -> list:
    return []


def test_a_test_sharing_a_module_fixture_is_in_its_modules_group(shared, request):
    mark = request.node.get_closest_marker("xdist_group")
    assert mark is not None and mark.args == (__name__,)
    if getattr(request.config.option, "loadgroup", False):  # a worker of --dist loadgroup
        assert request.node.nodeid.endswith(f"@{__name__}"), request.node.nodeid


def test_a_test_alone_is_in_no_group(request):
    assert request.node.get_closest_marker("xdist_group") is None
    assert "@" not in request.node.nodeid
