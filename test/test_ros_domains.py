"""Test fixtures: every concurrently running test gets a ROS domain of its own."""


def test_concurrent_workers_never_share_a_ros_domain():
    from conftest import domain_for

    for workers in (1, 2, 3, 4, 7):
        for run in (0, 12345, 99991):
            ids = {w: {domain_for(w, workers, run, k) for k in range(200)} for w in range(workers)}
            assert all(10 <= d <= 99 for v in ids.values() for d in v)
            for a in range(workers):
                for b in range(a + 1, workers):
                    assert not ids[a] & ids[b]
            # a worker cycles through its ids: the next test gets a different domain than the last one
            assert all(domain_for(0, workers, run, k) != domain_for(0, workers, run, k + 1) for k in range(50)) \
                or 90 // workers == 1


def test_a_domain_range_keeps_a_suite_inside_it():
    from conftest import domain_for

    for workers in (1, 2):
        ids = {w: {domain_for(w, workers, 777, k, 40, 54) for k in range(100)} for w in range(workers)}
        assert all(40 <= d <= 54 for v in ids.values() for d in v)
        assert workers == 1 or not ids[0] & ids[1]
