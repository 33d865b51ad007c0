"""Where the tasks of a tiled map build run: in this process, in order (SerialRunner), or as Dask tasks
(DaskRunner), each task waiting only for the tasks it depends on.

A task is idempotent: it reads files that are final before it starts and publishes its outputs by atomic renames,
so running it twice (Dask reruns the tasks of a worker that died) publishes the same bytes.
"""
import collections
import time
import uuid

Task = collections.namedtuple("Task", "key name fn args deps")
Task.__doc__ = """key: unique id; name: what the task does, for messages; fn(*args) runs it; deps: keys it waits for
(tasks are listed after their dependencies)."""


class BuildError(Exception):
    """A tiled build that stopped: the message names the task and why."""


def _call(fn, args, _deps):
    # _deps are the dependencies' results: passing them makes Dask start this task only after them.
    return fn(*args)


class SerialRunner:
    """Runs the tasks one after another in this process (`--workers 0`)."""

    def __init__(self, wrap=None):
        self.wrap = wrap  # wrap(task) -> callable replacing task.fn (tests inject faults with it)
        self.workers = 0

    def run(self, tasks):
        results = {}
        for t in tasks:
            fn = self.wrap(t) if self.wrap else t.fn
            try:
                results[t.key] = fn(*t.args)
            except (ValueError, RuntimeError, OSError) as e:
                raise BuildError("%s: %s" % (t.name, e)) from e
        return results


class DaskRunner:
    """Runs the tasks on a dask.distributed cluster through `client`; stops at the first failed task."""

    def __init__(self, client, wrap=None):
        self.client = client
        self.wrap = wrap
        self.workers = len(client.scheduler_info().get("workers", {}))

    def run(self, tasks):
        from distributed import as_completed

        token = uuid.uuid4().hex[:8]
        futures, names = {}, {}
        for t in tasks:
            fn = self.wrap(t) if self.wrap else t.fn
            future = self.client.submit(_call, fn, t.args, [futures[d] for d in t.deps], key="hpds-%s-%s" % (t.key, token),
                                        pure=False)
            futures[t.key] = future
            names[future.key] = t
        results = {}
        try:
            for future in as_completed(list(futures.values())):
                t = names[future.key]
                try:
                    results[t.key] = future.result()
                except Exception as e:  # noqa: BLE001 -- any task failure stops the build with its name
                    raise BuildError("%s: %s" % (t.name, _describe(e))) from e
        finally:
            pending = [f for f in futures.values() if not f.done()]
            if pending:
                self.client.cancel(pending)
                self._wait_until_idle(token)
        return results

    def _wait_until_idle(self, token, timeout=300.0):
        # A cancelled task that already runs on a worker goes on to its end (C++ cannot be interrupted): wait for it,
        # so that nothing of this build is still being written when run() returns.
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            busy = self.client.run(_running_keys, token, on_error="ignore")
            if not any(busy.values()):
                return
            time.sleep(0.05)


def _running_keys(token, dask_worker=None):
    return [k for k in list(getattr(dask_worker, "active_threads", {}).values()) if str(k).endswith(token)]


def _describe(error):
    try:
        from distributed import KilledWorker
    except ImportError:  # pragma: no cover
        KilledWorker = ()
    if isinstance(error, KilledWorker):
        return ("the workers running it died every time it was tried (%s); it published nothing, and the build "
                "stopped without a manifest" % error)
    return "%s: %s" % (type(error).__name__, error)
