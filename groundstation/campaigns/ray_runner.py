"""Sorties as Ray tasks (``--backend ray``, the optional ``peregrine[cluster]`` extra).

:class:`RayRunner` implements :class:`~.runner.SortieRunner` with the same :func:`run_job` the
process pool runs, so a job gives the same outcome on either. It joins the cluster at
``--ray-address`` / ``RAY_ADDRESS``, or starts a private Ray on this machine: loopback only,
``workers`` CPUs, no dashboard, no usage statistics, shut down when the runner closes.
Every cluster node must have this version of peregrine installed (the tasks import it).
"""

from __future__ import annotations

import importlib.util
import os
import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from .definitions import CampaignError
from .runner import (
    LocalPoolRunner,
    SortieJob,
    SortieOutcome,
    default_workers,
    run_job,
)

BACKENDS = ("process", "ray")
INSTALL_HINT = "--backend ray needs Ray, which is not installed: pip install 'peregrine[cluster]'"
LOCAL_OBJECT_STORE_BYTES = 128 * 1024 * 1024  # outcomes are small; the default takes 30 % of RAM


def ray_available() -> bool:
    return importlib.util.find_spec("ray") is not None


@contextmanager
def _env(**values: str) -> Iterator[None]:
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """Fail fast on a ``host:port`` nobody answers at (``ray.init`` retries for minutes)."""
    if "://" in address or address == "auto":
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise CampaignError(
            f"--ray-address {address!r}: expected HOST:PORT, ray://HOST:PORT or auto"
        )
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise CampaignError(f"cannot reach the Ray cluster at {address}: {exc}") from None


class RayRunner:
    """Run sorties as Ray tasks (one CPU each); outcomes come back in job order.

    Use as a context manager to keep one Ray connection (or local Ray) over several
    :meth:`run` calls; otherwise each call connects and disconnects.
    """

    def __init__(self, address: str | None = None, workers: int | None = None) -> None:
        if not ray_available():
            raise CampaignError(INSTALL_HINT)
        self.address = address or os.environ.get("RAY_ADDRESS") or None
        if self.address is not None and workers is not None:
            raise CampaignError(
                "--workers sizes the process pool or a local Ray; a Ray cluster "
                f"({self.address}) schedules on all its CPUs"
            )
        self.workers = (workers or default_workers()) if self.address is None else None
        if self.workers is not None and self.workers < 1:
            raise CampaignError("--workers must be at least 1")
        self._ray: Any = None
        self._started_local = False

    def __enter__(self) -> RayRunner:
        self._connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _connect(self) -> Any:
        if self._ray is not None:
            return self._ray
        # Read when ray is imported and by the processes it starts: no usage report, and
        # (local Ray) every server on 127.0.0.1 rather than the machine's public address.
        env = {"RAY_USAGE_STATS_ENABLED": "0"}
        if self.address is None:
            env["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
        with _env(**env):
            import ray
            from ray._private import ray_constants

            if ray.is_initialized():
                raise CampaignError("Ray is already initialised in this process")
            try:
                if self.address is None:
                    ray_constants.ENABLE_RAY_CLUSTER = False  # if ray was imported before
                    info = ray.init(
                        num_cpus=self.workers,
                        include_dashboard=False,
                        object_store_memory=LOCAL_OBJECT_STORE_BYTES,
                        log_to_driver=False,
                        configure_logging=False,
                    )
                    self._started_local = True
                    host = info.address_info["address"].rsplit(":", 1)[0]
                    if host != "127.0.0.1":
                        ray.shutdown()
                        raise CampaignError(f"local Ray listens on {host}, not 127.0.0.1; refused")
                else:
                    _check_reachable(self.address)
                    ray.init(address=self.address, log_to_driver=False, configure_logging=False)
            except CampaignError:
                raise
            except Exception as exc:  # ray raises ConnectionError, ValueError, RuntimeError
                where = self.address or "a local Ray"
                first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc)
                raise CampaignError(f"cannot start or join {where}: {first}") from None
        self._ray = ray
        return ray

    def close(self) -> None:
        """Disconnect (and stop the local Ray this runner started)."""
        if self._ray is not None:
            self._ray.shutdown()
            self._ray = None

    def run(
        self,
        jobs: Sequence[SortieJob],
        on_done: Callable[[SortieOutcome], None] | None = None,
    ) -> list[SortieOutcome]:
        keep = self._ray is not None
        ray = self._connect()
        try:
            task = ray.remote(num_cpus=1, max_retries=1)(run_job)
            pending = [task.remote(job) for job in jobs]
            outcomes: list[SortieOutcome] = []
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                out = ray.get(done[0])
                outcomes.append(out)
                if on_done:
                    on_done(out)
        finally:
            if not keep:
                self.close()
        outcomes.sort(key=lambda o: o.index)
        return outcomes


def make_runner(
    backend: str = "process", workers: int | None = None, ray_address: str | None = None
) -> LocalPoolRunner | RayRunner:
    """The runner for ``--backend``, checked here before any sortie runs; use it as a context
    manager (``with make_runner(...) as runner``) to connect first and clean up after."""
    if backend not in BACKENDS:
        raise CampaignError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if workers is not None and workers < 1:
        raise CampaignError("--workers must be at least 1")
    if backend == "process":
        if ray_address is not None:
            raise CampaignError("--ray-address needs --backend ray")
        return LocalPoolRunner(workers)
    return RayRunner(ray_address, workers)
