"""The shared parallel mapper: sequential for one worker, a real Dask cluster otherwise."""

import pytest

from bench.parallel import mapper, sequential_map


def _square(x):
    return x * x


def test_one_worker_is_the_in_process_map():
    with mapper(workers=1) as m:
        assert m is sequential_map
        assert m(_square, [1, 2, 3]) == [1, 4, 9]


def test_two_worker_cluster_maps_in_order():
    with mapper(workers=2) as m:
        assert m is not sequential_map
        assert m(_square, range(10)) == [x * x for x in range(10)]
        assert m(_square, []) == []


def test_bad_worker_count_is_rejected():
    with pytest.raises(ValueError, match="workers"):
        with mapper(workers=0):
            pass
