"""Where the work of a run goes: this process, local worker processes, or a Ray cluster.

A unit of work is one call of a module-level function with picklable arguments (a sequence to
render, a sequence to localize); results come back to this process, which alone writes the
run's shared state (the manifest, results files).  Whatever the executor and the number of
workers, each unit computes the same bytes (DESIGN.md, "Determinism").

Local workers die with their parent: each asks the kernel for SIGKILL when the parent dies
(Linux ``PR_SET_PDEATHSIG``) and also watches its parent id, so a killed run leaves no worker
writing.  Progress travels on a plain ``multiprocessing`` queue (no manager process to orphan).
"""
from __future__ import annotations

import os
import threading
import time

from pad_design.errors import InputError

EXECUTORS = ("local", "ray")
_progress_sink = None  # where report_progress goes: the worker's queue, or the caller's callback


def _die_with_parent(parent_pid: int) -> None:
    try:  # Linux: the kernel kills us when the parent goes
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def watch():
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(0.5)

    threading.Thread(target=watch, daemon=True).start()
    if os.getppid() != parent_pid:  # the parent died before the hook was in place
        os._exit(1)


def _init_worker(parent_pid: int, queue, setup) -> None:
    global _progress_sink
    _die_with_parent(parent_pid)
    _progress_sink = queue.put
    import cv2

    cv2.setNumThreads(1)  # the pool is the parallelism
    if setup is not None:
        setup()


def report_progress(n: int) -> None:
    """Called by a unit of work: ``n`` more steps done (frames)."""
    if _progress_sink is not None:
        _progress_sink(n)


def _call(fn_args):
    fn, args = fn_args
    return fn(*args)


def run_units(fn, units: list, workers: int = 1, executor: str = "local", ray_address: str | None = None,
              progress=None, setup=None):
    """Yield ``fn(*unit)`` for every unit, in the order they finish.  ``progress(n)`` is called in
    this process as units report steps (local) or finish (Ray: once per unit, with its result)."""
    if executor not in EXECUTORS:
        raise InputError(f"--executor: {executor!r} is not one of {', '.join(EXECUTORS)}")
    if executor == "ray":
        yield from _run_ray(fn, units, ray_address, setup, workers)
        return
    if workers <= 1 or len(units) <= 1:
        global _progress_sink
        _progress_sink = progress
        try:
            for u in units:
                yield fn(*u)
        finally:
            _progress_sink = None
        return
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    # concurrent.futures, not multiprocessing.Pool: a worker that dies (a crash in a native library, the
    # OOM killer) breaks the pool and fails the run; Pool replaced it silently and waited for its lost
    # unit forever
    pool = ProcessPoolExecutor(min(workers, len(units)), mp_context=ctx, initializer=_init_worker,
                               initargs=(os.getpid(), queue, setup))
    try:
        pending = {pool.submit(_call, (fn, u)) for u in units}
        while pending:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            _drain(queue, progress)
            for f in done:
                try:
                    r = f.result()
                except BrokenProcessPool:
                    raise RuntimeError(f"a worker process died while running {getattr(fn, '__name__', fn)} "
                                       "(killed, or crashed in native code); nothing of its unit was kept") from None
                yield r
        _drain(queue, progress)
        pool.shutdown(wait=True)
    except BaseException:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:  # no orphan keeps rendering
            proc.terminate()
        raise
    finally:
        queue.close()


def _drain(queue, progress) -> None:
    import queue as q

    while True:
        try:
            n = queue.get_nowait()
        except q.Empty:
            return
        if progress:
            progress(n)


def _run_ray(fn, units: list, address: str | None, setup, workers: int):
    try:
        import ray
    except ImportError:
        raise InputError("--executor ray: Ray is not installed (pip install 'hvloc[ray]')") from None
    if not ray.is_initialized():
        try:
            # without an address, a local instance with --workers CPUs; with one, the cluster's own
            ray.init(address=address, num_cpus=None if address else max(1, workers), include_dashboard=False,
                     log_to_driver=False, ignore_reinit_error=True, configure_logging=False)
        except (ConnectionError, ValueError, RuntimeError) as err:
            raise InputError(f"--ray-address {address or '(local)'}: cannot start or join a Ray cluster ({err})") from None

    @ray.remote(num_cpus=1)
    def unit(fn, args):
        import cv2

        cv2.setNumThreads(1)
        if setup is not None:
            setup()
        return fn(*args)

    refs = [unit.remote(fn, u) for u in units]
    try:
        while refs:
            done, refs = ray.wait(refs, num_returns=1)
            yield ray.get(done[0])
    except BaseException:
        for r in refs:
            ray.cancel(r, force=True)
        raise
