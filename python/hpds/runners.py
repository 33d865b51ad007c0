"""Where the tasks of a tiled map build run: in this process, in order (SerialRunner), or as Dask tasks
(DaskRunner), each task waiting only for the tasks it depends on.

A task is idempotent: it reads files that are final before it starts and publishes its outputs by atomic renames,
so running it twice (Dask reruns the tasks of a worker that died) publishes the same bytes.
"""
import collections
import itertools
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
    """Runs the tasks on a dask.distributed cluster through `client`; stops at the first failed task.

    A worker that dies takes every task queued on it along, not only the one that killed it; Dask fails a task once
    it was on `allowed-failures` + 1 dying workers. Such a task (KilledWorker) is submitted again, with the tasks
    waiting for it, up to `retries` times. A task that still fails is only a suspect: a task queued behind a crashing
    one can share its fate every time. Once nothing else of the build is in flight, each suspect runs once more on
    its own; one that completes goes on (with what waits on it), and one whose workers die while it runs alone is the
    one that crashes them: it stops the build with its own name.

    A cluster left without workers (their nannies could not replace the ones that died, or they were shut down)
    would leave the build waiting for ever: after `no_worker_timeout` seconds without a worker it stops, saying so.
    """

    def __init__(self, client, wrap=None, retries=2, no_worker_timeout=120.0):
        self.client = client
        self.wrap = wrap
        self.retries = retries
        self.no_worker_timeout = no_worker_timeout
        self.workers = len(client.scheduler_info().get("workers", {}))

    def _completed(self, pending):
        """The futures of `pending` as they complete (its set may grow meanwhile), as iterating it would give them,
        but watching that the cluster still has a worker to run them."""
        alone_since, checked = None, 0.0
        while not pending.is_empty():
            batch = pending.next_batch(block=False)
            if batch:
                alone_since = None
                yield from batch
                continue
            now = time.monotonic()
            if now - checked >= 1.0:
                checked = now
                if self.client.scheduler_info().get("workers"):
                    alone_since = None
                elif alone_since is None:
                    alone_since = now
                elif now - alone_since > self.no_worker_timeout:
                    raise BuildError("the Dask cluster has had no workers for %.0f s with %d tasks of the build "
                                     "unfinished (workers that died were not replaced): give it workers or restart "
                                     "it, and run the build again" % (now - alone_since, pending.count()))
            time.sleep(0.05)

    def run(self, tasks):
        from distributed import as_completed

        token = uuid.uuid4().hex[:8]
        dependents = collections.defaultdict(list)
        for t in tasks:
            for d in t.deps:
                dependents[d].append(t.key)
        current, task_of, attempts, results = {}, {}, collections.Counter(), {}
        serial = itertools.count()  # every submission its own key: Dask would hand back an erred future

        def submit(t):
            fn = self.wrap(t) if self.wrap else t.fn
            future = self.client.submit(_call, fn, t.args, [current[d] for d in t.deps],
                                        key="hpds-%s-%d-%s" % (t.key, next(serial), token), pure=False)
            current[t.key] = future
            task_of[future.key] = t
            return future

        def resubmit(key):
            # The task and every task waiting on it (their futures fail with the dependency's error), in task order.
            todo, stack = set(), [key]
            while stack:
                k = stack.pop()
                if k not in todo and k not in results:
                    todo.add(k)
                    stack.extend(dependents[k])
            attempts[key] += 1
            return [submit(t) for t in tasks if t.key in todo]

        order = {t.key: i for i, t in enumerate(tasks)}
        suspects, alone = set(), None  # keys out of retries; the key now running with nothing else in flight
        pending = as_completed([submit(t) for t in tasks])
        try:
            while True:
                for future in self._completed(pending):
                    t = task_of[future.key]
                    if current.get(t.key) is not future:
                        continue  # superseded by a resubmission
                    try:
                        results[t.key] = future.result()
                    except Exception as e:  # noqa: BLE001 -- any task failure stops the build with its name
                        culprit = _killed_task(e, task_of) or t
                        if not _is_killed_worker(e) or culprit.key == alone:
                            raise BuildError("%s: %s" % (culprit.name, _describe(e))) from e
                        if attempts[culprit.key] < self.retries:
                            pending.update(resubmit(culprit.key))
                        else:
                            suspects.add(culprit.key)  # its dependents failed with it: they wait for its verdict
                # Nothing of this build is in flight: the first suspect in task order (what it waits for is done)
                # runs alone; its dependents wait for it.
                if not suspects:
                    break
                alone = min(suspects, key=order.get)
                suspects.discard(alone)
                pending = as_completed(resubmit(alone))
        finally:
            unfinished = [f for f in current.values() if not f.done()]
            if unfinished:
                self.client.cancel(unfinished)
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


def _killed_worker_type():
    try:
        from distributed import KilledWorker
    except ImportError:  # pragma: no cover
        return ()
    return KilledWorker


def _is_killed_worker(error):
    return isinstance(error, _killed_worker_type())


def _killed_task(error, task_of):
    # A task waiting on a killed one fails with the dependency's KilledWorker: attribute it to the dependency.
    if not _is_killed_worker(error):
        return None
    return task_of.get(error.task)


def _describe(error):
    if _is_killed_worker(error):
        return ("the workers running it died every time it was tried (%s); it published nothing, and the build "
                "stopped without a manifest" % error)
    return "%s: %s" % (type(error).__name__, error)
