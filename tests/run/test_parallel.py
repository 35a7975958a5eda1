"""The process pools of the benchmarks and sweeps (``mpcform.run.parallel``): spawned workers with
single-threaded BLAS unless the caller chose otherwise, the parent's environment restored, results
in submission order, a worker's error surfacing in the parent with the worker's traceback."""

from __future__ import annotations

import math
import os
import time

import pytest

from mpcform._validate import positive
from mpcform.errors import ValidationError
from mpcform.run.parallel import THREAD_VARIABLES, blas_threads, process_pool, single_threaded_env

INPUTS = [300, 1, 2000, 7, 0, 45]


@pytest.fixture
def no_thread_variables(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)


@pytest.mark.usefixtures("no_thread_variables")
def test_single_threaded_env_sets_the_unset_variables_and_restores(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    with single_threaded_env():
        assert os.environ["OPENBLAS_NUM_THREADS"] == "1" and os.environ["MKL_NUM_THREADS"] == "1"
        assert os.environ["OMP_NUM_THREADS"] == "4"  # the caller's choice is kept
        assert blas_threads() == "1"
    assert "OPENBLAS_NUM_THREADS" not in os.environ and "MKL_NUM_THREADS" not in os.environ
    assert os.environ["OMP_NUM_THREADS"] == "4" and blas_threads() == "unset"


@pytest.mark.usefixtures("no_thread_variables")
def test_single_threaded_env_restores_after_an_error() -> None:
    with pytest.raises(RuntimeError), single_threaded_env():
        raise RuntimeError("inside")
    assert not any(name in os.environ for name in THREAD_VARIABLES)


@pytest.mark.usefixtures("no_thread_variables")
def test_workers_run_single_threaded_blas_unless_the_caller_set_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MKL_NUM_THREADS", "3")
    with process_pool(1) as pool:
        seen = list(pool.map(os.getenv, THREAD_VARIABLES))
    assert seen == ["1", "1", "3"]
    assert "OPENBLAS_NUM_THREADS" not in os.environ  # the parent's environment is restored


def test_results_come_in_order_and_do_not_depend_on_the_workers() -> None:
    expected = [math.factorial(k) for k in INPUTS]
    with process_pool(1) as pool:
        one = list(pool.map(math.factorial, INPUTS))
    with process_pool(2) as pool:
        two = list(pool.map(math.factorial, INPUTS))
        futures = [pool.submit(math.factorial, k) for k in INPUTS]
        submitted = [f.result() for f in futures]
    assert one == two == submitted == expected


def test_a_worker_error_surfaces_with_the_workers_traceback() -> None:
    with process_pool(2) as pool:
        ok = pool.submit(math.sqrt, 4.0)
        bad = pool.submit(math.sqrt, -1.0)
        with pytest.raises(ValueError, match="math domain error") as info:
            bad.result()
        assert ok.result() == 2.0  # one task's error leaves the pool and the others alone
        assert pool.submit(math.sqrt, 9.0).result() == 3.0
    remote = str(info.value.__cause__)
    assert "Traceback" in remote and "ValueError: math domain error" in remote


def test_a_fresh_process_per_task_with_max_tasks_per_child() -> None:
    with process_pool(1, max_tasks_per_child=1) as pool:
        fresh = {pool.submit(os.getpid).result() for _ in range(3)}
    with process_pool(1) as pool:
        kept = {pool.submit(os.getpid).result() for _ in range(3)}
    assert len(fresh) == 3 and len(kept) == 1 and os.getpid() not in fresh | kept


def test_leaving_the_block_early_cancels_the_queued_tasks() -> None:
    with pytest.raises(RuntimeError, match="stop"), process_pool(1) as pool:
        futures = [pool.submit(time.sleep, 0.3) for _ in range(8)]
        raise RuntimeError("stop")
    assert sum(f.cancelled() for f in futures) >= 5  # at most the running one and one queued ran


def test_a_worker_validation_error_surfaces_as_itself() -> None:
    with process_pool(1) as pool:
        with pytest.raises(ValidationError) as info:
            pool.submit(positive, "dt", -1).result()
    assert info.value.field == "dt" and "expected a finite number > 0" in str(info.value)
