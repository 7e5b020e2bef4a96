"""The local executor: worker processes on this machine, one task each at a time."""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
import time

from .tasks import KILL_HOOK_ENV, Event, Task, run_task, worker_init

__all__ = ["LocalPool"]


class _Worker:
    def __init__(self, ctx) -> None:
        self.conn, child = ctx.Pipe()
        # A forkserver child inherits the server's environment, not ours: pass the hook on.
        hook = os.environ.get(KILL_HOOK_ENV)
        self.process = ctx.Process(target=_worker_main, args=(child, hook), daemon=True)
        self.process.start()
        child.close()
        self.tid: int | None = None
        self.since = 0.0


class _ParentGone(BaseException):
    """Raised in a worker whose batch parent died: the task stops (its ``with`` blocks remove
    its temporary files) and the worker exits quietly."""


def _on_sigterm(signum, frame) -> None:
    raise _ParentGone()


def _watch_parent(conn, running: list[int]) -> None:
    """SIGTERM this worker when its pipe turns readable while it runs a task: the parent died
    (end of file) or is closing the pool (it sends nothing else to a busy worker)."""
    while True:
        task = running[0]
        if task and multiprocessing.connection.wait([conn], _PARENT_POLL_S) and running[0] == task:
            os.kill(os.getpid(), signal.SIGTERM)
            return
        if not task:
            time.sleep(_PARENT_POLL_S)


#: How often an idle worker's watch looks again, and how long a busy one waits on its pipe [s].
_PARENT_POLL_S = 0.5


def _worker_main(conn, kill_hook: str | None = None) -> None:
    """A local worker: run tasks from the pipe until it closes, or until the batch is gone
    (the parent died or closed the pool, the pipe broke, SIGTERM): then exit quietly, without
    a traceback; a task cut short removes its temporary files on the way out."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    signal.signal(signal.SIGTERM, _on_sigterm)
    running = [0]  # the number of the task running, 0 between tasks
    threading.Thread(target=_watch_parent, args=(conn, running), daemon=True).start()
    if kill_hook:
        os.environ[KILL_HOOK_ENV] = kill_hook
    else:
        os.environ.pop(KILL_HOOK_ENV, None)
    try:
        worker_init()
        count = 0
        while True:
            message = conn.recv()
            if message is None:
                return
            tid, task = message
            count += 1
            running[0] = count
            result = run_task(task)
            running[0] = 0
            conn.send((tid, result))
    except (EOFError, OSError, _ParentGone):  # the parent is gone: nobody to report to
        return


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


class LocalPool:
    """Worker processes, one task each at a time; a dead worker is replaced.

    Workers fork from a server process that has imported cloth_usd once (the
    ``forkserver`` start method), so starting or replacing one is quick and never
    forks a parent that holds threads.

    Args:
        workers: at most this many tasks run at once.
        job_timeout: seconds a task may run before its worker is killed, None for no limit.
    """

    def __init__(self, workers: int, job_timeout: float | None) -> None:
        self.ctx = multiprocessing.get_context("forkserver")
        self.ctx.set_forkserver_preload(["cloth_usd.batch.tasks", "cloth_usd.baking", "cloth_usd.usd.read",
                                         "cloth_usd.usd.write", "tqdm.auto"])
        self.size = workers
        self.timeout = job_timeout
        self.workers: list[_Worker] = []

    def free(self) -> int:
        return self.size - sum(w.tid is not None for w in self.workers)

    def submit(self, tid: int, task: Task) -> None:
        worker = next((w for w in self.workers if w.tid is None), None)
        if worker is None:
            worker = _Worker(self.ctx)
            self.workers.append(worker)
        worker.tid, worker.since = tid, time.monotonic()
        worker.conn.send((tid, task))

    def wait(self, timeout: float) -> list[Event]:
        busy = [w for w in self.workers if w.tid is not None]
        if not busy:
            return []
        multiprocessing.connection.wait([w.conn for w in busy] + [w.process.sentinel for w in busy], timeout)
        events = []
        for w in busy:
            try:
                if w.conn.poll():
                    tid, result = w.conn.recv()
                    events.append(Event(tid, result))
                    w.tid = None
                    continue
            except (EOFError, OSError):
                pass
            if not w.process.is_alive():
                w.process.join()
                events.append(Event(w.tid, None, died=f"worker {_death(w.process.exitcode)}"))
                self._drop(w)
            elif self.timeout is not None and time.monotonic() - w.since > self.timeout:
                w.process.kill()
                w.process.join()
                events.append(Event(w.tid, None, died=f"timed out after {self.timeout:g} s (worker killed)"))
                self._drop(w)
        return events

    def _drop(self, worker: _Worker) -> None:
        worker.conn.close()
        self.workers.remove(worker)

    def close(self) -> None:
        for w in self.workers:
            try:
                w.conn.send(None)
            except OSError:
                pass
        deadline = time.monotonic() + 5.0
        for w in self.workers:
            w.process.join(max(0.0, deadline - time.monotonic()))
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()
        self.workers.clear()
