"""The suite's schedule (conftest.TEST_GROUPS, `make test`'s ``--dist loadgroup``): the long files first, each group
whole on one worker."""
from pathlib import Path

HERE = Path(__file__).parent


def test_every_scheduled_file_exists_once():
    from conftest import TEST_GROUPS

    files = [f for _, fs in TEST_GROUPS for f in fs]
    assert len(files) == len(set(files)) and len({g for g, _ in TEST_GROUPS}) == len(TEST_GROUPS)
    assert [f for f in files if not (HERE / f).is_file()] == []        # a renamed file would silently lose its place


def test_schedule_puts_the_groups_first_and_keeps_each_file_whole_and_in_order():
    from conftest import TEST_GROUPS, schedule

    first, second = TEST_GROUPS[0][1][0], TEST_GROUPS[1][1][0]
    files = ["test_a.py", second, "test_a.py", first, "test_b.py", second, first]
    order, groups = schedule(files)
    assert sorted(order) == list(range(len(files)))
    assert [files[i] for i in order] == [first, first, second, second, "test_a.py", "test_a.py", "test_b.py"]
    assert order == [3, 6, 1, 5, 0, 2, 4]                        # stable: a file's items keep their order
    assert groups == ["test_a.py", TEST_GROUPS[1][0], "test_a.py", TEST_GROUPS[0][0], "test_b.py", TEST_GROUPS[1][0],
                      TEST_GROUPS[0][0]]
    # the files of one group share its name (one worker runs them)
    if len(TEST_GROUPS[0][1]) > 1:
        assert len(set(schedule(list(TEST_GROUPS[0][1]))[1])) == 1
