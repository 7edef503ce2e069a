"""run_jobs: results in job order, progress from worker processes, single-threaded workers, errors re-raised."""
from __future__ import annotations

import io
import json
import os
from concurrent.futures.process import BrokenProcessPool

import pytest

from gg_core.errors import InputError
from gg_core.jobs import Progress
from gg_core.parallel import default_workers, run_jobs


def square_in_worker(job: int, step) -> tuple[int, int, str]:
    import torch

    step(f"job {job}", 2)
    return job * job, torch.get_num_threads(), os.environ.get("OMP_NUM_THREADS", "")


def fail_on_two(job: int, step) -> int:
    if job == 2:
        raise InputError("frame 2 is corrupt", "seq/cam0/rgb_images/000002.png", "re-export it")
    step()
    return job


def die_on_two(job: int, step) -> int:
    if job == 2:
        os._exit(3)                     # a worker killed mid-job (out of memory, a signal) says nothing
    return job


def tensor_sum(job, step) -> float:
    return float(job.sum())


def _progress(total: int) -> tuple[Progress, io.StringIO]:
    stream = io.StringIO()
    return Progress("test", total, "jsonl", stream), stream


def test_jobs_run_in_single_threaded_workers_and_report_progress_in_order_of_jobs():
    progress, stream = _progress(6)
    results = run_jobs(square_in_worker, [1, 2, 3], 2, progress)
    assert [r[0] for r in results] == [1, 4, 9]
    assert all(r[1] == 1 and r[2] == "1" for r in results)
    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    assert sorted(line["message"] for line in lines) == ["job 1", "job 2", "job 3"]
    assert lines[-1]["step"] == 6


def test_one_worker_runs_in_this_process():
    progress, _ = _progress(2)
    assert run_jobs(square_in_worker, [3], 4, progress)[0][:1] == (9,)
    assert run_jobs(fail_on_two, [1, 3], 1, progress) == [1, 3]


def test_a_workers_input_error_reaches_the_parent_intact_after_the_others_finish():
    progress, stream = _progress(3)
    with pytest.raises(InputError) as caught:
        run_jobs(fail_on_two, [1, 2, 3], 2, progress)
    assert str(caught.value) == "gg: error: frame 2 is corrupt, seq/cam0/rgb_images/000002.png, re-export it"
    assert len(stream.getvalue().splitlines()) == 2       # jobs 1 and 3 finished and reported


def test_a_worker_that_dies_fails_the_run_instead_of_hanging_it():
    progress, _ = _progress(3)
    with pytest.raises(BrokenProcessPool):
        run_jobs(die_on_two, [1, 2, 3], 2, progress)


def test_default_workers_is_one_per_job_at_most_one_per_core():
    assert default_workers(1) == 1 and 1 <= default_workers(100) <= (os.cpu_count() or 1)


def halve_then_square(job: tuple[str, int], step) -> tuple[str, int]:
    kind, value = job
    step(f"{kind} {value}")
    return ("half", value // 2) if kind == "start" else ("done", value * value)


def follow_halves(job: tuple[str, int], result: tuple[str, int]) -> tuple[str, int] | None:
    return result if result[0] == "half" else None


def test_follow_up_jobs_run_after_their_job_and_give_its_result():
    for workers in (1, 2):
        progress, stream = _progress(6)
        results = run_jobs(halve_then_square, [("start", 8), ("start", 6), ("start", 10)], workers, progress,
                           then=follow_halves)
        assert results == [("done", 16), ("done", 9), ("done", 25)]
        messages = [json.loads(line)["message"] for line in stream.getvalue().splitlines()]
        assert sorted(messages) == ["half 3", "half 4", "half 5", "start 10", "start 6", "start 8"]
        for value, half in ((8, 4), (6, 3), (10, 5)):     # each follow-up after its own job
            assert messages.index(f"start {value}") < messages.index(f"half {half}")


def test_sending_a_tensor_to_a_worker_leaves_the_parents_numpy_views_of_it_valid():
    """multiprocessing's own pickler would move the tensor's storage into shared memory and free the buffer a
    NumPy view of it still points at (parallel.py's docstring); the view must stay the tensor's memory."""
    import torch

    tensors = [torch.arange(100_000, dtype=torch.float64) * k for k in (1, 2)]
    views = [t.numpy() for t in tensors]
    progress, _ = _progress(2)
    assert run_jobs(tensor_sum, tensors, 2, progress) == [float(t.sum()) for t in tensors]
    assert all(t.data_ptr() == v.ctypes.data for t, v in zip(tensors, views))   # checked before reading the views
    assert all(float(v.sum()) == float(t.sum()) for t, v in zip(tensors, views))
