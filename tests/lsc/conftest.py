"""The `problem` fixture: every constant problem of `CONSTANT_PROBLEMS`, once per module."""
import pytest

from tests.support.problems import CONSTANT_PROBLEMS


@pytest.fixture(params=sorted(CONSTANT_PROBLEMS), scope="module")
def problem(request):
    return CONSTANT_PROBLEMS[request.param]()
