"""Independent jobs in single-threaded worker processes, their progress funnelled into one `Progress`.

Why processes with one thread each: the stages' inner loops are many small torch ops between numba rasterizer
calls, which a second thread in the same process slows down. Measured on the 2-core development machine, demo
capture walk, frames 1-9 registered: 17.3-18.0 s per frame with one thread, 18.9-20.0 s with two (and 96 s of
system time in spin-waits). Independent sequences in separate processes use every core instead.

Jobs run in `spawn`ed processes (no forked torch or numba state); a worker reports progress by
`step(message, advance)`, which puts it on a queue the parent drains into its `Progress`. Cancelling the add-on's
job kills the whole process group, workers included (blender_addon/jobs.py).

Jobs and results cross as plain pickle bytes, never through multiprocessing's own pickler: torch registers a
reduction with it that moves every pickled CPU tensor's storage into shared memory in place, in the sending
process, and frees the old buffer, so a NumPy view of that tensor the sender still holds (`tensor.numpy()`: the
simulator's Numeric arrays are such views of the cloth's tensors) points at freed memory. Found in session 47: a
`gg diagnose` with two workers left its own baseline simulator rolling the recordings out at 585 km (a fresh copy
of it: 8.6 mm) once the trial jobs had been sent; in a short test the freed view segfaulted on reading.
"""
from __future__ import annotations

import multiprocessing
import os
import pickle
import queue
import time
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Callable, Sequence, TypeVar

from .errors import InputError
from .jobs import Progress

J = TypeVar("J")
R = TypeVar("R")
Step = Callable[..., None]            # step(message: str = "", advance: int = 1)
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
_POLL_S = 0.2
_GRACE_S = 2.0                         # s the queue must stay quiet after a worker died
_queue = None                         # the worker's progress queue (set by _init_worker)


def default_workers(jobs: int) -> int:
    """One worker per job, at most one per core."""
    return max(1, min(jobs, os.cpu_count() or 1))


def check_workers(requested: int | None) -> None:
    """A stage's `--workers` (None: one per core) is bad input below 1; checked before the stage's work starts."""
    if requested is not None and requested < 1:
        raise InputError(f"--workers must be at least 1, got {requested}", "--workers", "pass 1 or more")


def worker_count(requested: int | None, jobs: int) -> int:
    """The `--workers` asked for, or default_workers."""
    return default_workers(jobs) if requested is None else requested


def run_jobs(fn: Callable[[J, Step], R], jobs: Sequence[J], workers: int, progress: Progress,
             then: Callable[[J, R], J | None] | None = None) -> list[R]:
    """[fn(job, step) for job in jobs], in `workers` processes (in this process, one after another, for one
    worker or one job). `then(job, result)` may name a follow-up job, which `fn` runs as soon as a worker is
    free; the job's result is then its follow-up's (stage 2: a sequence's fits, then its stereo step, so that a
    worker done fitting refines a finished sequence instead of idling). A follow-up starts once its job's progress
    has reached `progress` (its end marker drained), so a job's messages precede its follow-up's. `fn` and the
    jobs must pickle. A failing job's exception is raised here once the other jobs have finished, so what they
    write is kept (the stages resume from it)."""
    if workers <= 1 or len(jobs) <= 1:
        return [_chain(fn, job, progress.step, then) for job in jobs]
    ctx = multiprocessing.get_context("spawn")
    messages = ctx.Queue()
    results: list = [None] * len(jobs)
    errors: list[BaseException] = []
    ended: set[int] = set()                 # runs whose end marker was drained: all their steps were before it
    waiting: dict[Future, float] = {}       # done runs whose end marker is still on its way: since when
    with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=ctx, initializer=_init_worker,
                             initargs=(messages,)) as pool:
        pending: dict[Future, tuple[int, J, int]] = {}
        started = 0                         # runs submitted, follow-ups included; a run's key is its number

        def submit(i: int, job: J) -> None:
            nonlocal started
            pending[pool.submit(_run, pickle.dumps((fn, job)), started)] = (i, job, started)
            started += 1

        for i, job in enumerate(jobs):
            submit(i, job)
        quiet_since = None
        while pending or len(ended) < started:
            for future in [f for f in pending if f.done()]:
                i, job, key = pending[future]
                # a follow-up waits for its job's progress (workers' queues are not ordered across processes)
                if (future.exception() is None and key not in ended
                        and time.monotonic() - waiting.setdefault(future, time.monotonic()) < _GRACE_S):
                    continue
                del pending[future]
                waiting.pop(future, None)
                if future.exception() is not None:
                    errors.append(future.exception())
                    continue
                result = pickle.loads(future.result())
                follow = then(job, result) if then is not None else None
                if follow is None:
                    results[i] = result
                else:
                    submit(i, follow)
            try:
                item = messages.get(timeout=_POLL_S)
            except queue.Empty:
                # a worker that died says nothing: once every job is done, wait for the queue to stay quiet
                if pending:
                    continue
                quiet_since = quiet_since or time.monotonic()
                if time.monotonic() - quiet_since > _GRACE_S:
                    break
                continue
            if item[0] is None:
                ended.add(item[1])
            else:
                progress.step(*item)
    if errors:
        raise errors[0]
    return results


def _chain(fn: Callable[[J, Step], R], job: J, step: Step, then: Callable[[J, R], J | None] | None) -> R:
    result = fn(job, step)
    follow = then(job, result) if then is not None else None
    return result if follow is None else _chain(fn, follow, step, then)


def _init_worker(messages) -> None:
    global _queue
    _queue = messages
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"


def _run(task: bytes, key: int) -> bytes:
    """The pickled (fn, job)'s result, pickled (see the module docstring: not by multiprocessing's pickler)."""
    import numba  # noqa: PLC0415 - after _init_worker limited the threads
    import torch  # noqa: PLC0415

    torch.set_num_threads(1)
    numba.set_num_threads(1)

    def step(message: str = "", advance: int = 1) -> None:
        _queue.put((message, advance))

    try:
        fn, job = pickle.loads(task)
        return pickle.dumps(fn(job, step))
    finally:
        _queue.put((None, key))   # this run ended: all its steps are on the queue before this
