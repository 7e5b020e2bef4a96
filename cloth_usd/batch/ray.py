"""The Ray executor of :func:`cloth_usd.batch.run_batch` (``pip install 'cloth-usd[ray]'``).

Each task is a Ray task with ``max_retries``: Ray runs it again when its worker dies,
and a worker process keeps its model cache across the tasks it runs. Ray is imported
only here, when a batch asks for it. On a cluster every node needs cloth-usd installed
and the stages and outputs on a shared file system.
"""

from __future__ import annotations

import logging
import os
import time
from typing import Any

from ..errors import ArgumentError
from .tasks import KILL_HOOK_ENV, Event, Task, run_task

__all__ = ["RayPool"]

log = logging.getLogger(__name__)


def _import_ray():
    try:
        import ray
    except ImportError:
        raise ArgumentError("--executor ray needs Ray, which is not installed: "
                            "pip install 'cloth-usd[ray]'") from None
    return ray


class RayPool:
    """Runs batch tasks as Ray tasks, at most ``size`` at a time.

    Args:
        workers: CPUs of the local Ray started when ``address`` is None.
        retries: Ray's ``max_retries`` (re-runs after a worker dies).
        address: an existing cluster (``ray://host:10001``, ``auto``), None for a local one.
        job_timeout: seconds a task may run before it is cancelled (and run again).
    """

    def __init__(self, *, workers: int, retries: int, address: str | None = None,
                 job_timeout: float | None = None) -> None:
        ray = self._ray = _import_ray()
        self._started = not ray.is_initialized()
        if self._started:
            env = {KILL_HOOK_ENV: os.environ[KILL_HOOK_ENV]} if os.environ.get(KILL_HOOK_ENV) else {}
            options: dict[str, Any] = dict(address=address, include_dashboard=False, log_to_driver=False,
                                           logging_level=logging.WARNING,
                                           runtime_env={"env_vars": env} if env else None)
            if address is None:
                options["num_cpus"] = workers
            try:
                ray.init(**options)
            except ConnectionError as exc:
                raise ArgumentError(f"--address {address}: cannot connect to a Ray cluster ({exc})") from None
        cpus = int(ray.cluster_resources().get("CPU", workers))
        self.size = max(1, cpus if address is not None else min(workers, cpus))
        self.timeout = job_timeout
        self._remote = ray.remote(num_cpus=1, max_retries=retries, retry_exceptions=False)(run_task)
        self._refs: dict[Any, tuple[int, float]] = {}  # ObjectRef -> (tid, submitted)

    def free(self) -> int:
        return self.size - len(self._refs)

    def submit(self, tid: int, task: Task) -> None:
        self._refs[self._remote.remote(task)] = (tid, time.monotonic())

    def wait(self, timeout: float) -> list[Event]:
        ray = self._ray
        if not self._refs:
            return []
        ready, rest = ray.wait(list(self._refs), num_returns=1, timeout=timeout)
        if ready and rest:
            ready += ray.wait(rest, num_returns=len(rest), timeout=0)[0]
        events = []
        for ref in ready:
            tid, _since = self._refs.pop(ref)
            try:
                events.append(Event(tid, ray.get(ref)))
            except ray.exceptions.RayError as exc:  # the worker died on every attempt
                why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                events.append(Event(tid, None, died=f"Ray {type(exc).__name__}: {why}", final=True))
        if self.timeout is not None:
            now = time.monotonic()
            for ref, (tid, since) in list(self._refs.items()):
                if now - since > self.timeout:
                    ray.cancel(ref, force=True)
                    del self._refs[ref]
                    events.append(Event(tid, None, died=f"timed out after {self.timeout:g} s (cancelled)"))
        return events

    def close(self) -> None:
        for ref in self._refs:
            self._ray.cancel(ref, force=True)
        self._refs.clear()
        if self._started:
            self._ray.shutdown()
