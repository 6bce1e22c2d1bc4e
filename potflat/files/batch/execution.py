"""Running a batch: each scan through all stages in a local process pool or on a Dask
cluster, one failing scan never stopping the others; the summary (``summary.csv``,
``summary.json``) and the report written at the end, and a scan's ``manifest.json`` as it
finishes (:mod:`.manifest`)."""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import os
import re
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from potflat import __version__
from potflat import _heap
from potflat._interrupts import raise_interrupt
from potflat._jit import numba_threads
from potflat.errors import InvalidOptionError, PotflatError
from potflat.files.batch.config import Batch, ScanJob
from potflat.files.batch.manifest import (
    MANIFEST,
    is_complete,
    job_inputs,
    job_key,
    read_manifest,
)
from potflat.files.batch.report import write_report
from potflat.files.pipeline import FIGURES, ZONE_FIGURES, run_scan
from potflat.io.atomic import output_lock, own_subfolder, write_bytes_atomic, write_json_atomic

#: Statuses of a scan in a batch summary.
STATUSES = ("done", "skipped", "failed", "interrupted", "cancelled")
#: Start method of local worker processes: fresh interpreters, so no Numba thread pool or
#: lock is inherited from the parent (fork is unsafe once threads exist).
START_METHOD = "spawn"
#: How long to try reaching a Dask scheduler before giving up.
CONNECT_TIMEOUT = "20s"
#: Columns of ``summary.csv``.
CSV_COLUMNS = ("name", "status", "seconds", *FIGURES, *ZONE_FIGURES, "error", "scan", "output")


# --------------------------------------------------------------------------- one scan
@dataclass(frozen=True)
class ScanReport:
    """The outcome of one scan in a batch (a row of the summary).

    Attributes
    ----------
    name : str
        Output name.
    scan : str
        Scan path.
    output : str
        Scan output folder.
    status : str
        ``done``, ``skipped`` (already complete), ``failed``, ``interrupted`` (stopped while it
        ran) or ``cancelled`` (the batch was interrupted before it started).
    seconds : float
        Wall time spent on this scan in this run.
    figures : dict
        Distortion figures of the relaxed result (:data:`potflat.files.pipeline.FIGURES`), and
        of its painted zone and plain surface (:data:`potflat.files.pipeline.ZONE_FIGURES`).
    error : str
        One-line error message for failed scans, else ``""``.
    """

    name: str
    scan: str
    output: str
    status: str
    seconds: float = 0.0
    figures: dict = dataclasses.field(default_factory=dict)
    error: str = ""

    def row(self) -> dict[str, Any]:
        """The report as a flat dict (the summary's columns)."""
        row = {"name": self.name, "status": self.status, "seconds": round(self.seconds, 3)}
        row.update({k: self.figures.get(k) for k in (*FIGURES, *ZONE_FIGURES)})
        row.update(error=self.error, scan=self.scan, output=self.output)
        return row


def one_line(exc: BaseException, *, limit: int = 400) -> str:
    """An exception as one line: the message of user errors, ``Type: message`` otherwise."""
    text = " ".join(re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", str(exc)).split())  # no colour codes
    if not isinstance(exc, PotflatError):
        text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _report(job: ScanJob, status: str, seconds: float = 0.0, figures: dict | None = None,
            error: str = "") -> ScanReport:
    return ScanReport(name=job.name, scan=str(job.scan), output=str(job.out_dir), status=status,
                      seconds=seconds, figures=dict(figures or {}), error=error)


def run_job(job: ScanJob, key: str, *, threads: int | None = None) -> ScanReport:
    """Run one scan of a batch; never raises an ``Exception`` (failures become reports).

    The old manifest is first replaced by a partial one (``complete: false``, the marker of
    potflat's own unfinished outputs); the new one is written last, after every output, so an
    interrupted or failed scan is never taken as complete. The scan folder's outputs stay one
    consistent set (:func:`potflat.run_scan`: an earlier run's are replaced whole, or restored
    when this one fails). ``error.log`` in the scan folder keeps the traceback of a failure.
    """

    start = time.perf_counter()
    try:
        own_subfolder(job.out_dir.parent, job.out_dir, create=True)
    except PotflatError as exc:
        return _report(job, "failed", error=one_line(exc))
    old = read_manifest(job.out_dir) or {}
    old_outputs = old.get("outputs") if isinstance(old.get("outputs"), dict) else {}
    try:
        # marker first: the folder holds potflat's own (partial) outputs until the final manifest
        write_json_atomic(job.out_dir / MANIFEST, {"complete": False, "name": job.name, "scan": str(job.scan),
                                                    "potflat": __version__, "outputs": old_outputs})
        with numba_threads(threads):
            result = run_scan(job.scan, job.out_dir, name=job.name, rollout=job.options.rollout,
                              relax=job.options.relax, bake=job.options.bake)
        outputs = {}
        for p in sorted(result.paths.values()):
            p = Path(p).resolve()
            rel = p.relative_to(job.out_dir.resolve()).as_posix()
            outputs[rel] = p.stat().st_size
        with contextlib.suppress(FileNotFoundError):
            (job.out_dir / "error.log").unlink()
        seconds = time.perf_counter() - start
        figures = {**result.figures, **result.zone_figures}
        write_json_atomic(job.out_dir / MANIFEST, {
            "complete": True, "key": key, "name": job.name, "scan": str(job.scan), "potflat": __version__,
            "options": job.options_json(), "outputs": outputs,
            "inputs": [str(p) for p in job_inputs(job)], "figures": figures,
            "seconds": round(seconds, 3)})
        return _report(job, "done", seconds, figures)
    except Exception as exc:  # noqa: BLE001 - failure isolation: any error is this scan's
        with contextlib.suppress(Exception):
            write_bytes_atomic(job.out_dir / "error.log", traceback.format_exc().encode())
        return _report(job, "failed", time.perf_counter() - start, error=one_line(exc))


def _run_job_on_dask_worker(job: ScanJob, key: str) -> ScanReport:
    """:func:`run_job` with Numba threads shared among the worker's task threads."""
    from distributed import get_worker

    worker = get_worker()
    nthreads = getattr(getattr(worker, "state", None), "nthreads", None) or worker.nthreads
    return run_job(job, key, threads=max(1, _cores() // max(1, nthreads)))


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def default_workers(n_scans: int) -> int:
    """Default number of local worker processes: one per core, at most one per scan."""
    return max(1, min(_cores(), n_scans))


# --------------------------------------------------------------------------- summary
@dataclass(frozen=True)
class BatchSummary:
    """Every scan's outcome, in batch order.

    Attributes
    ----------
    batch : Path
        The batch file.
    output : Path
        The output folder (holding ``summary.csv`` and ``summary.json``).
    reports : tuple of ScanReport
    seconds : float
        Wall time of the whole batch.
    """

    batch: Path
    output: Path
    reports: tuple
    seconds: float

    @property
    def counts(self) -> dict[str, int]:
        """Number of scans per status."""
        return {s: sum(r.status == s for r in self.reports) for s in STATUSES}

    @property
    def exit_code(self) -> int:
        """0 if every scan is done or skipped, 1 if any failed, was interrupted or cancelled."""
        return 0 if all(r.status in ("done", "skipped") for r in self.reports) else 1

    def to_dict(self) -> dict[str, Any]:
        """The summary as JSON-ready data (the content of ``summary.json``)."""

        return {"batch": str(self.batch), "output": str(self.output), "potflat": __version__,
                "seconds": round(self.seconds, 3), "counts": self.counts,
                "scans": [r.row() for r in self.reports]}

    def write(self) -> tuple[Path, Path]:
        """Write ``summary.json`` and ``summary.csv`` into the output folder, atomically."""

        json_path = write_json_atomic(self.output / "summary.json", self.to_dict())
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, lineterminator="\n")
        writer.writeheader()
        for report in self.reports:
            writer.writerow({k: ("" if v is None else v) for k, v in report.row().items()})
        csv_path = write_bytes_atomic(self.output / "summary.csv", buffer.getvalue().encode())
        return csv_path, json_path


# --------------------------------------------------------------------------- scheduling
def run_batch(batch: Batch, *, workers: int | None = None, scheduler: str | None = None,
              force: bool = False, on_result: Callable[[ScanReport], None] | None = None,
              on_plan: Callable[[int, int], None] | None = None) -> BatchSummary:
    """Run every scan of ``batch``; write and return the summary.

    Parameters
    ----------
    batch : Batch
        From :func:`load_batch`.
    workers : int, optional
        Local worker processes (default :func:`default_workers`); 1 runs in this process.
        Each worker gets ``cores // workers`` Numba threads. Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``) to run the scans on
        instead; needs ``pip install 'dask[distributed]'`` here and on the workers, and the
        scan and output paths must be the same on every worker (a shared file system).
    force : bool
        Redo every scan, even those whose outputs are complete.
    on_result : callable, optional
        Called with each :class:`ScanReport` as it arrives (skipped scans first).
    on_plan : callable, optional
        Called once with (scans to run, scans skipped) before any work.

    Returns
    -------
    BatchSummary
        Also written as ``summary.json``, ``summary.csv`` and the report ``index.html``
        (:mod:`potflat.files.report`) in ``batch.output``, even when interrupted (unfinished scans are
        then ``interrupted``).
    """

    start = time.perf_counter()
    wall_start = time.time()
    reports: dict[int, ScanReport] = {}
    todo: list[tuple[int, ScanJob, str]] = []
    emit = on_result or (lambda report: None)
    if workers is not None and workers < 1:
        raise InvalidOptionError(f"--workers must be at least 1, got {workers}")
    for job in batch.jobs:  # a folder under the output planted as a link: refused before any work
        own_subfolder(batch.output, job.out_dir, create=False)
    client = _dask_client(scheduler) if scheduler is not None else None  # fail before any work
    with output_lock(batch.output, what="potflat batch"):
        try:
            for index, job in enumerate(batch.jobs):
                try:
                    key = job_key(job)
                except OSError as exc:  # the scan vanished or became unreadable since validation
                    reports[index] = _report(job, "failed", error=f"{job.scan}: cannot read: "
                                             f"{exc.strerror or one_line(exc)}; check the file")
                    continue
                manifest = None if force else is_complete(job, key)
                if manifest is not None:
                    reports[index] = _report(job, "skipped", figures=manifest.get("figures"))
                else:
                    todo.append((index, job, key))
            if on_plan is not None:
                on_plan(len(todo), len(reports))
            for index in sorted(reports):
                emit(reports[index])

            def record(index: int, report: ScanReport) -> None:
                reports[index] = report
                emit(report)

            if client is not None:
                _run_dask(todo, client, record)
            else:
                n = workers or default_workers(len(todo))
                if n == 1 or len(todo) <= 1:
                    for index, job, key in todo:
                        record(index, run_job(job, key))
                else:
                    _run_pool(todo, n, record)
        finally:
            if client is not None:
                client.close()
            ordered = tuple(reports.get(i) or _unfinished(job, wall_start) for i, job in enumerate(batch.jobs))
            summary = BatchSummary(batch=batch.path, output=batch.output, reports=ordered,
                                   seconds=time.perf_counter() - start)
            with contextlib.suppress(PotflatError, OSError):
                summary.write()

                write_report(summary)
    return summary


def _unfinished(job: ScanJob, since: float) -> ScanReport:
    """The report of a scan that has none when the batch stops: ``interrupted`` if it started
    (its partial manifest was written in this run, at wall time ``since`` or later), with the
    time it ran, else ``cancelled``."""
    manifest = job.out_dir / MANIFEST
    try:
        started = manifest.stat().st_mtime
    except OSError:
        started = None
    if started is not None and started >= since - 1.0 and (read_manifest(job.out_dir) or {}).get("complete") is False:
        return _report(job, "interrupted", max(0.0, time.time() - started),
                       error="interrupted while it ran; rerun the batch to redo it")
    return _report(job, "cancelled", error="not started: the batch was interrupted; rerun it to resume")


def _worker_start(parent: int) -> None:
    """Set-up of a local worker process: Ctrl-C is the parent's to handle (it ends the workers);
    SIGTERM interrupts the scan (its temporaries are removed) and ends the worker; the worker is
    sent SIGTERM when the parent dies, however it dies (Linux)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, raise_interrupt)
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent died before the line above
        os._exit(130)


def _run_job_in_worker(job: ScanJob, key: str, threads: int, heap_tuning: bool) -> ScanReport:
    """:func:`run_job` in a pool worker, with the heap tuning allowed when the batch's process
    allowed it (:func:`potflat._heap.heap_tuning`); an interrupt (SIGTERM from the parent) ends
    the worker once the scan's temporaries are removed, so it can never start a queued scan."""
    try:
        with _heap.heap_tuning() if heap_tuning else contextlib.nullcontext():
            return run_job(job, key, threads=threads)
    except KeyboardInterrupt:
        os._exit(130)


#: Seconds the workers get to remove their temporaries after the batch is interrupted.
WORKER_STOP_SECONDS = 10.0


def _run_pool(todo: list, workers: int, record: Callable[[int, ScanReport], None]) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    threads, heap_tuning = max(1, _cores() // workers), _heap.heap_tuning_allowed()
    context = multiprocessing.get_context(START_METHOD)
    crashed = []
    start = dict(mp_context=context, initializer=_worker_start, initargs=(os.getpid(),))
    with ProcessPoolExecutor(max_workers=workers, **start) as pool:
        try:
            futures = {pool.submit(_run_job_in_worker, job, key, threads, heap_tuning): (index, job, key)
                       for index, job, key in todo}
            for future in as_completed(futures):
                index, job, key = futures[future]
                try:
                    record(index, future.result())
                except BrokenProcessPool:
                    crashed.append((index, job, key))
        except BaseException:
            _stop_workers(pool)
            raise
    # A worker process died (killed, out of memory, crashed in native code): the pool is
    # broken and every unfinished scan is affected. Retry each alone in a fresh process, so
    # only the scan that kills its process again is reported failed.
    for index, job, key in sorted(crashed, key=lambda item: item[0]):
        with ProcessPoolExecutor(max_workers=1, **start) as pool:
            try:
                report = pool.submit(_run_job_in_worker, job, key, threads, heap_tuning).result()
            except BrokenProcessPool:
                report = _report(job, "failed", error=(
                    "the worker process died (killed, out of memory or crashed); run this scan "
                    f"alone with 'potflat run {job.scan}' to see why"))
            except BaseException:
                _stop_workers(pool)
                raise
        record(index, report)


def _stop_workers(pool) -> None:
    """Cancel the queued scans and end the workers of ``pool`` (SIGTERM: they remove their
    temporaries), killing those still alive after :data:`WORKER_STOP_SECONDS`."""
    from multiprocessing.connection import wait

    processes = list((getattr(pool, "_processes", None) or {}).values())  # shutdown() forgets them
    pool.shutdown(wait=False, cancel_futures=True)
    running = {}  # sentinel -> process: the sentinel is ready once the process has ended, whichever
    for proc in processes:  # thread reaps it (the executor's own thread may, so join can return early)
        with contextlib.suppress(Exception):
            proc.terminate()
            running[proc.sentinel] = proc
    deadline = time.monotonic() + WORKER_STOP_SECONDS
    with contextlib.suppress(OSError, ValueError):  # a sentinel closed meanwhile: kill what is left
        while running and time.monotonic() < deadline:
            for sentinel in wait(list(running), max(0.0, deadline - time.monotonic())):
                running.pop(sentinel)
    for proc in running.values():
        with contextlib.suppress(Exception):
            proc.kill()


def _dask_client(address: str):
    """A Dask client connected to the scheduler at ``address`` (clear errors otherwise)."""
    try:
        from distributed import Client
    except ImportError:
        raise InvalidOptionError("--scheduler needs Dask distributed, which is not installed; "
                                 "install it with: pip install 'dask[distributed]'") from None
    try:
        return Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InvalidOptionError(f"cannot connect to the Dask scheduler at {address}: "
                                 f"{one_line(exc)}; check the address or start one with "
                                 "'dask scheduler'") from None


def _run_dask(todo: list, client, record: Callable[[int, ScanReport], None]) -> None:
    from distributed import as_completed

    futures = {client.submit(_run_job_on_dask_worker, job, key, pure=False,
                             key=f"potflat-{job.name}-{key[:12]}-{index}"): (index, job)
               for index, job, key in todo}
    try:
        for future in as_completed(futures, loop=client.loop):
            index, job = futures[future]
            try:
                report = future.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails this scan only
                report = _report(job, "failed", error=f"on the Dask cluster: {one_line(exc)}")
            record(index, report)
    except BaseException:
        client.cancel(list(futures))
        raise
