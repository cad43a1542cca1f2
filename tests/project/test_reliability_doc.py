"""docs/reliability.md names, for every class of bad input, the test that proves it: each named
test must exist, so the table cannot point at a test that was renamed or removed."""
import re

from tests.support import ROOT


def named_tests(text):
    """``(file, test)`` pairs of the table: ``tests/f.py::name`` and the ``::name`` that follow it in a cell."""
    pairs = []
    for cell in text.split("|"):
        current = None
        for ref in re.findall(r"`(tests/[\w/]+\.py)?(?:::(\w+))?[^`]*`", cell):
            path, name = ref
            current = path or current
            if current and name:
                pairs.append((current, name))
    return pairs


def test_named_tests_parse():
    assert named_tests("| `tests/a.py::x`, `::y` | `tests/b.py` |") == [("tests/a.py", "x"), ("tests/a.py", "y")]


def test_every_test_the_reliability_table_names_exists():
    pairs = named_tests((ROOT / "docs" / "reliability.md").read_text())
    assert len(pairs) > 30
    missing = [f"{f}::{t}" for f, t in pairs
               if not (ROOT / f).exists() or not re.search(rf"^def {t}\(", (ROOT / f).read_text(), re.M)]
    assert not missing, missing
