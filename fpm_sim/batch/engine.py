"""The engine of the pose and design loops: chunks of work on ``dask.distributed``, streamed to disk.

:func:`run_chunks` calls ``fn(item, **kwargs)`` for every item (a chunk of poses, or a design and a chunk
of poses) and returns the results in order:

- ``scheduler="local"``: a :class:`distributed.LocalCluster` of ``workers`` processes with one thread each
  (the default ``workers`` is the machine's CPU count);
- ``scheduler=None`` (the default): the same, unless the work is too small to pay for starting the
  cluster (a few seconds): with one worker, a single chunk or fewer than :data:`LOCAL_CLUSTER_MIN_ITEMS`
  items (poses) it runs in this process;
- ``scheduler="tcp://host:port"``: an existing cluster, used as it is (nothing is started or closed);
- ``scheduler="serial"``: in this process, always.

With a ``store`` folder every finished chunk is written there as it arrives (``<key>.pkl``, the key a hash
of the function name, the item and the keyword arguments; written to a temporary name and renamed, so a
killed run leaves no half-written chunk). ``resume=True`` loads the chunks already there instead of
computing them again; without it the folder is emptied first. A tqdm progress bar counts items (the
``weights``, e.g. poses per chunk) and the dashboard address is printed when the cluster serves one.

Chunk size: a task costs the scheduler about a millisecond (``docs/design.md``, "Scale on paper"), so a
chunk should hold at least ~0.5 s of work: :func:`chunk_size` aims at four chunks per worker, between
:data:`MIN_CHUNK` and :data:`MAX_CHUNK` poses.
"""

from __future__ import annotations

import hashlib
import logging
import math
import multiprocessing
import os
import pickle
import shutil
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fpm_sim.errors import FpmSimError

__all__ = [
    "LOCAL_CLUSTER_MIN_ITEMS",
    "MAX_CHUNK",
    "MIN_CHUNK",
    "EngineError",
    "EngineOptions",
    "chunk_size",
    "chunk_store",
    "run_chunks",
    "spawn_pool",
    "split",
]

MIN_CHUNK = 16
"""Fewest poses per task (at ~1-3 ms per pose, below this the scheduler's per-task cost shows)."""
MAX_CHUNK = 512
"""Most poses per task (keeps the progress bar moving and a killed run's loss small)."""
LOCAL_CLUSTER_MIN_ITEMS = 4000
"""Fewest poses (grid points, unreachable ones included) for which the default engine starts a local cluster:
starting one costs ~3.4 s and a computed pose ~2.5 ms, so on two workers the cluster pays off from about
2700 computed poses, some 3500 grid points of a dense map (docs/design.md, "Scale on paper")."""


class EngineError(FpmSimError):
    """The engine cannot run as asked (bad scheduler address, worker count, store folder)."""


@dataclass(frozen=True)
class EngineOptions:
    """Where and how the chunks run.

    Parameters
    ----------
    scheduler
        ``"local"`` (a local cluster of ``workers`` processes), ``None`` (the same when the work is large
        enough, see the module doc), ``"serial"`` (this process), or the address of a running scheduler
        (``tcp://host:port``), used unchanged.
    workers
        Processes of the local cluster (default: the CPU count). One worker runs in this process.
    chunk
        Items per task (poses); ``None`` picks :func:`chunk_size`.
    store
        Folder for finished chunks (streamed as they arrive); ``None`` keeps them in memory only.
    resume
        Reuse the chunks already in ``store`` (a killed run continues where it stopped).
    progress
        Show a progress bar.
    desc
        Label of the progress bar.
    connect_timeout_s
        How long to try to reach a remote scheduler.
    """

    scheduler: str | None = None
    workers: int | None = None
    chunk: int | None = None
    store: Path | None = None
    resume: bool = False
    progress: bool = False
    desc: str = "poses"
    connect_timeout_s: float = 20.0

    def __post_init__(self) -> None:
        if self.workers is not None and self.workers < 1:
            raise EngineError("must be >= 1", parameter="workers", value=self.workers)
        if self.chunk is not None and self.chunk < 1:
            raise EngineError("must be >= 1", parameter="chunk", value=self.chunk)
        if self.resume and self.store is None:
            raise EngineError("needs a store folder (the output of the interrupted run)", parameter="resume")
        s = self.scheduler
        if s is not None and s not in ("local", "serial") and "://" not in s:
            raise EngineError(
                "unknown scheduler",
                parameter="scheduler",
                value=s,
                hint="use 'local', 'serial' or a scheduler address like tcp://127.0.0.1:8786",
            )

    @property
    def n_workers(self) -> int:
        return self.workers or os.cpu_count() or 1

    @property
    def remote(self) -> bool:
        return self.scheduler is not None and "://" in self.scheduler


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored in this block (main thread only: elsewhere a no-op); the previous handler restored after."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is None:
        yield
        return
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def spawn_pool(workers: int, initializer: Callable[..., None] | None = None, initargs: tuple[Any, ...] = ()) -> Any:
    """A ``spawn`` :class:`multiprocessing.pool.Pool` of ``workers`` processes, each given ``initargs`` once through
    ``initializer`` (picklable data only), whose workers ignore Ctrl-C.

    A terminal's Ctrl-C goes to the whole process group: workers that took it would each print their own
    ``KeyboardInterrupt`` traceback (also after the command's one "interrupted" line). These inherit SIGINT ignored
    (set while they start; Python keeps an ignored SIGINT ignored), so only this process is interrupted; its caller
    stops them with ``pool.terminate()`` (as leaving a ``with pool:`` block does), never ``close()`` and ``join()``,
    which would wait for their queued work. A Ctrl-C in the milliseconds the workers take to start is lost.
    """
    with _sigint_ignored():
        return multiprocessing.get_context("spawn").Pool(workers, initializer=initializer, initargs=initargs)


def chunk_store(out: str | Path) -> Path:
    """Folder of a run's finished chunks, beside its output ``out`` (removed when the run completes)."""
    out = Path(out)
    return out.parent / f"{out.name}.partial"


def chunk_size(n_items: int, n_workers: int) -> int:
    """Items per task: about four tasks per worker, clipped to ``[MIN_CHUNK, MAX_CHUNK]``."""
    return max(MIN_CHUNK, min(MAX_CHUNK, math.ceil(n_items / (4 * max(n_workers, 1)))))


def split(items: Sequence[Any], size: int) -> list[list[Any]]:
    """``items`` in consecutive chunks of ``size`` (the last may be shorter)."""
    return [list(items[i : i + size]) for i in range(0, len(items), size)]


def _key(fn: Callable[..., Any], item: Any, kwargs: dict[str, Any]) -> str:
    text = repr((fn.__module__, fn.__qualname__, item, sorted(kwargs.items())))
    return hashlib.sha1(text.encode()).hexdigest()[:20]


def _write(path: Path, result: Any) -> None:
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    with open(tmp, "wb") as fh:
        pickle.dump(result, fh, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)


def _prepare_store(opts: EngineOptions) -> Path | None:
    if opts.store is None:
        return None
    store = Path(opts.store)
    if store.exists() and not opts.resume:
        shutil.rmtree(store)
    store.mkdir(parents=True, exist_ok=True)
    return store


def _load(store: Path | None, keys: list[str]) -> dict[int, Any]:
    done: dict[int, Any] = {}
    if store is None:
        return done
    for i, k in enumerate(keys):
        path = store / f"{k}.pkl"
        if path.exists():
            try:
                with open(path, "rb") as fh:
                    done[i] = pickle.load(fh)
            except (OSError, EOFError, pickle.UnpicklingError):
                path.unlink(missing_ok=True)  # a damaged chunk is computed again
    return done


def run_chunks(
    fn: Callable[..., Any],
    items: Sequence[Any],
    *,
    kwargs: dict[str, Any] | None = None,
    weights: Sequence[int] | None = None,
    options: EngineOptions | None = None,
) -> list[Any]:
    """``[fn(item, **kwargs) for item in items]``, on the engine ``options`` describe (see module doc).

    ``fn`` must be importable (a module-level function) and its arguments picklable. ``weights`` (one per
    item, default 1) is what the progress bar counts.

    Raises
    ------
    EngineError
        The scheduler cannot be reached or the store folder cannot be written.
    """
    opts = options or EngineOptions()
    kw = dict(kwargs or {})
    items = list(items)
    wts = list(weights) if weights is not None else [1] * len(items)
    keys = [_key(fn, it, kw) for it in items]
    try:
        store = _prepare_store(opts)
    except OSError as exc:
        raise EngineError(
            f"cannot use the chunk folder {opts.store} ({exc})", parameter="out", hint="pick another output"
        ) from exc
    results = _load(store, keys)
    todo = [i for i in range(len(items)) if i not in results]
    bar = None
    if opts.progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=sum(wts), initial=sum(wts[i] for i in results), desc=opts.desc, unit="pose")

    def finished(i: int, res: Any) -> None:
        results[i] = res
        if store is not None:
            _write(store / f"{keys[i]}.pkl", res)
        if bar is not None:
            bar.update(wts[i])

    try:
        small = sum(wts[i] for i in todo) < LOCAL_CLUSTER_MIN_ITEMS and opts.scheduler is None
        serial = opts.scheduler == "serial" or (not opts.remote and (opts.n_workers == 1 or len(todo) <= 1 or small))
        if serial:
            for i in todo:
                finished(i, fn(items[i], **kw))
        elif todo:
            _run_dask(fn, [(i, items[i], keys[i]) for i in todo], kw, opts, finished)
    finally:
        if bar is not None:
            bar.close()
    return [results[i] for i in range(len(items))]


def _run_dask(
    fn: Callable[..., Any],
    todo: list[tuple[int, Any, str]],
    kwargs: dict[str, Any],
    opts: EngineOptions,
    finished: Callable[[int, Any], None],
) -> None:
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    try:
        if opts.remote:
            client = Client(opts.scheduler, timeout=f"{opts.connect_timeout_s}s")
        else:
            dashboard = ":0" if _has_bokeh() else None
            cluster = LocalCluster(
                n_workers=min(opts.n_workers, len(todo)),
                threads_per_worker=1,
                processes=True,
                dashboard_address=dashboard,
                silence_logs=logging.ERROR,
            )
            client = Client(cluster)
    except OSError as exc:
        raise EngineError(
            f"cannot reach the Dask scheduler ({exc})", parameter="scheduler", value=opts.scheduler, hint="check it"
        ) from exc
    try:
        link = _dashboard(client)
        if link and opts.progress:
            print(f"Dask dashboard: {link}", file=sys.stderr)
        futures = {}
        for i, item, key in todo:
            fut = client.submit(fn, item, key=f"{fn.__name__}-{key}", pure=False, **kwargs)
            futures[fut] = i
        for fut in as_completed(list(futures)):
            finished(futures[fut], fut.result())
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _has_bokeh() -> bool:
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return False
    return True


def _dashboard(client: Any) -> str | None:
    """The dashboard address, or ``None`` if the scheduler serves none."""
    try:
        services = client.scheduler_info().get("services", {})
    except Exception:  # informational only: no dashboard address is not an error
        return None
    return client.dashboard_link if "dashboard" in services else None
