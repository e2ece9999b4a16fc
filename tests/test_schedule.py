"""The suite's own scheduling (tests/conftest.py): every module and test it names still exists."""

import importlib.util
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("suite_conftest", REPO / "tests" / "conftest.py")
conftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(conftest)
SHARED_FIXTURE_GROUPS, SLOW_FIRST, work_unit_rank = conftest.SHARED_FIXTURE_GROUPS, conftest.SLOW_FIRST, \
    conftest.work_unit_rank


def test_the_grouped_modules_exist():
    missing = [module for module in SHARED_FIXTURE_GROUPS if not (REPO / module).is_file()]
    assert not missing, f"SHARED_FIXTURE_GROUPS names modules that are gone: {missing}"


def test_the_slow_units_exist_and_come_first():
    groups = set(SHARED_FIXTURE_GROUPS.values())
    stale = []
    for unit in SLOW_FIRST:
        module, _, test = unit.partition("::")
        if unit in groups and not test:
            continue
        path = REPO / module
        name = re.sub(r"\[.*\]$", "", test)
        if not path.is_file() or (name and not re.search(rf"^def {re.escape(name)}\(", path.read_text(), re.M)):
            stale.append(unit)
    assert not stale, f"SLOW_FIRST names units that are gone: {stale}"
    assert len(set(SLOW_FIRST)) == len(SLOW_FIRST)
    assert [work_unit_rank(u) for u in SLOW_FIRST] == list(range(len(SLOW_FIRST)))
    assert work_unit_rank("tests/test_schedule.py::test_the_grouped_modules_exist") == len(SLOW_FIRST)
