"""Fit a whole database on dask.distributed: :func:`fit_database` (also ``rbrdf-fit batch``).

Each material is one independent task (:func:`fit.batch.tasks.run_material`) on a
``distributed`` cluster: by default a ``LocalCluster`` started for the run and closed after it,
with one single-threaded worker *process* per core (``workers``; the BLAS/OpenMP variables of
:data:`fit.batch.tasks.THREAD_ENV` set to 1, HiGHS with one thread), or any running cluster
given by the address of its scheduler (``scheduler="tcp://host:8786"``: the workers were
started by the user, e.g. ``dask scheduler`` and ``dask worker ADDRESS --nthreads 1``; they
must import this ``fit`` package and see the input and output paths).

Resume: before submitting, the client hashes every input and checks each output's manifest
(:mod:`fit.batch.keys`, :mod:`fit.batch.tasks`): materials whose outputs are all done are not
submitted, and a task skips what an earlier run completed. A run that is interrupted (Ctrl-C,
killed) loses only the tasks in flight; Ctrl-C cancels them, closes the cluster and leaves no
half-written file (outputs are renamed into place whole, temporary files of killed workers
are removed by the next run). A failure of one material is a row of the report with its
one-line error, never an exception.

The report (:mod:`fit.batch.report`) is written to ``OUT/report.csv``, ``OUT/report.md`` and
the chart ``OUT/report_coefficients.png`` (coefficients against tolerance), renamed into place
together at the end of the run.
"""
from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

from ..errors import BRDFFileError, FlagError, OutputError, display_text
from .inputs import collect_inputs, expand_inputs  # noqa: F401 - expand_inputs: the API before
from .keys import BatchOptions, BrdfOptions, CdfOptions, SamplerOptions
from .progress import ProgressClock
from .scheduler import CONNECT_TIMEOUT_S
from .report import BatchReport, plot_coefficients, rows_from_results
from .tasks import THREAD_ENV, run_material

REPORT_FILES = ("report.csv", "report.md", "report_coefficients.png")


def make_options(tols=(0.05,), cdf: bool = True, brdf_options: dict | None = None,
                 cdf_options: dict | None = None, sampler: bool = True,
                 sampler_time_limit_s: float | None = SamplerOptions.time_limit_s) -> BatchOptions:
    """:class:`BatchOptions` from plain arguments (unknown option names: ``ValueError``)."""
    if isinstance(tols, (int, float)):
        tols = (tols,)
    tols = tuple(dict.fromkeys(float(t) for t in tols))
    if not tols:
        raise ValueError("no tolerance")
    bo = dict(brdf_options or {})
    BrdfOptions(**bo)                      # unknown names raise TypeError -> ValueError below
    if sampler_time_limit_s is not None and not sampler_time_limit_s > 0:
        raise ValueError(f"sampler time limit {sampler_time_limit_s!r}: expected seconds > 0 or None (no limit)")
    return BatchOptions(tols=tols, brdf=bo, cdf=CdfOptions(**(cdf_options or {})) if cdf else None,
                        sampler=SamplerOptions(sampler_time_limit_s) if sampler else None)


def _check_options(options: BatchOptions) -> None:
    """``ValueError`` for a fit setting out of range at any tolerance: building each
    :class:`fit.rational.settings.BRDFFitSettings` validates it."""
    options.brdf_options()


def default_workers() -> int:
    """Cores this process may run on (``os.sched_getaffinity``, else ``os.cpu_count``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _start_client(workers: int | None, scheduler: str | None, timeout_s: float, worker_timeout_s: float):
    """``(client, cluster or None, n_workers)``: a local cluster of ``workers`` processes, or
    the scheduler at ``scheduler`` (:func:`fit.batch.scheduler.connect` within ``timeout_s``)
    with at least one worker within ``worker_timeout_s``."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        from .scheduler import connect

        client = connect(scheduler, timeout_s)
        try:
            client.wait_for_workers(1, timeout=worker_timeout_s)
        except (TimeoutError, OSError):
            client.close()
            raise FlagError("--scheduler", f"no worker joined {scheduler} within {worker_timeout_s:g} s") from None
        return client, None, len(client.scheduler_info(n_workers=-1)["workers"])
    n = workers or default_workers()
    # Worker processes start with SIGINT ignored (inherited through exec): Ctrl-C in a terminal
    # reaches the whole process group, and only this process must act on it (cancel, close the
    # cluster); workers killed by their own KeyboardInterrupt would print tracebacks.
    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               env=dict(THREAD_ENV), silence_logs=logging.ERROR)
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
    return Client(cluster), cluster, n


def fit_database(inputs, out, tols=(0.05,), *, cdf: bool = True, brdf_options: dict | None = None,
                 cdf_options: dict | None = None, sampler: bool = True,
                 sampler_time_limit_s: float | None = SamplerOptions.time_limit_s,
                 workers: int | None = None, scheduler: str | None = None,
                 progress: bool | None = None, log=None, on_progress=None,
                 connect_timeout_s: float = CONNECT_TIMEOUT_S, worker_timeout_s: float = 30.0,
                 report_only: bool = False) -> BatchReport:
    """Fit every material of ``inputs`` (files, folders, globs: :func:`fit.batch.inputs.collect_inputs`)
    into the folder ``out`` on dask.distributed and return the report (:class:`BatchReport`,
    also written to ``out/report.csv``, ``report.md`` and ``report_coefficients.png``).

    ``tols``: relative tolerance(s), one BRDF fit per material and tolerance
    (:func:`fit.fit_brdf`; ``brdf_options``: its other arguments, e.g. ``{"max_degree": 8}``,
    defaults those of ``rbrdf-fit brdf``); ``cdf``: also fit the inverse CDFs
    (:func:`fit.fit_cdf`; ``cdf_options``: :class:`fit.batch.keys.CdfOptions` fields, defaults
    those of ``rbrdf-fit cdf``); ``sampler``: store the fit's own inverse CDFs in each BRDF
    output, as ``rbrdf-fit brdf`` does (:func:`fit.sampling.model_sampler.embed_sampler`;
    ``sampler_time_limit_s``: its wall-clock bound, default None (none) as ``--sampler-time-limit``, None: no
    limit). ``workers``: local worker processes (default: one per core);
    ``scheduler``: address of a running scheduler instead (``workers`` ignored;
    :mod:`fit.batch.scheduler`: checked before anything is read, reached within
    ``connect_timeout_s`` seconds, a first worker within ``worker_timeout_s``).
    ``progress``: tqdm bar over materials on stderr (None: on when stderr is a terminal);
    ``on_progress(event)``: a :class:`fit.batch.progress.BatchProgress` per stage and per
    material finished (done/total, elapsed, estimate left); ``log(str)``: one line per material
    finished. ``report_only``: fit nothing, start no cluster: the report of the outputs already
    done (rows of outputs not done have status ``"missing"``).

    Every input is checked with ``stat`` before it is read or hashed: a file over its format's
    size, or a special file found in a folder, is that material's failure (a report row with
    its one-line error), the others are fitted. Bad arguments (no input, a missing file, an
    unusable output folder, a bad or unreachable scheduler) raise the one-line
    :class:`fit.errors.RbrdfError` before anything is fitted or the output folder created.
    ``KeyboardInterrupt`` cancels the tasks in flight and closes the local cluster before it
    propagates."""
    from tqdm import tqdm

    from ..formats import max_file_bytes
    from ..inputs import sha256_regular
    from ..outputs import OutputSet, check_output_dir

    t0 = time.perf_counter()
    clock = ProgressClock(on_progress)
    log = log or (lambda s: None)
    try:
        options = make_options(tols, cdf, brdf_options, cdf_options, sampler, sampler_time_limit_s)
        _check_options(options)
    except (TypeError, ValueError) as e:
        raise FlagError("options", str(e)) from None
    if scheduler is not None and not report_only:
        from .scheduler import check_address

        check_address(scheduler)
    out = check_output_dir(out, "--out")
    items = collect_inputs(inputs)
    if not items:
        raise BRDFFileError("<inputs>", "no input")
    clock.total = len(items)
    refused = sum(1 for i in items if i.error)
    clock.emit("inputs", f"{len(items)} measured files, {_mb(sum(i.size for i in items))}"
                         + (f", {refused} refused before reading" if refused else "") + "; hashing")

    results, pending, n_before, n_unread = [], [], 0, 0
    for item in items:
        p = item.path
        error = item.error
        if error is None:
            try:
                sha = sha256_regular(p, max_file_bytes(p), "measured file")
            except BRDFFileError as e:
                error = str(e)
        if error is not None:
            n_unread += 1
            results.append({"input": os.fspath(p), "name": p.stem, "sha256": None, "brdf": [], "cdf": None,
                            "error": error, "seconds": 0.0})
            continue
        # cheap in the client: which outputs are already done
        r, complete = material_status(p, options, out, sha)
        n_before += complete
        if complete or report_only:
            results.append(r)
        else:
            pending.append((p, sha))
    clock.done = len(results)
    clock.emit("hashed", f"{n_before} done before" + (f", {n_unread} failed (not readable)" if n_unread else "")
                         + f", {len(pending)} to fit")

    n_total = len(items)
    bar = tqdm(total=n_total, initial=n_total - len(pending), desc="materials", unit="material",
               disable=(not progress) if progress is not None else None)
    n_workers = 0
    client = cluster = None
    futures = {}

    def say(r: dict) -> None:
        line = _one_line(r)
        if not bar.disable:
            with tqdm.external_write_mode():
                log(line)
                clock.emit("material", line, r.get("name"), finished=True)
        else:
            log(line)
            clock.emit("material", line, r.get("name"), finished=True)

    try:
        if pending:
            from distributed import as_completed

            clock.emit("cluster", f"connecting to the scheduler {display_text(scheduler)}" if scheduler else
                       f"starting a local cluster of {workers or default_workers()} worker processes")
            client, cluster, n_workers = _start_client(workers, scheduler, connect_timeout_s, worker_timeout_s)
            _make_out(out)
            clock.emit("ready", f"{n_workers} worker{'s' if n_workers != 1 else ''} ready; "
                                f"{len(pending)} materials submitted")
            clock.start_fitting()
            for p, sha in pending:
                f = client.submit(run_material, os.fspath(Path(p).resolve()), options, os.fspath(Path(out).resolve()),
                                  sha, key=f"rbrdf-material-{p.stem}-{sha[:12]}-{_options_tag(options)}",
                                  pure=False, retries=0)
                futures[f] = (p, sha)
            for f in as_completed(futures):
                p, sha = futures[f]
                try:
                    r = f.result()
                    r["input"] = os.fspath(p)
                except (KeyboardInterrupt, SystemExit):
                    raise
                except BaseException as e:     # noqa: BLE001 - a lost worker is this material's failure
                    r = {"input": os.fspath(p), "name": p.stem, "sha256": sha, "brdf": [], "cdf": None,
                         "error": f"{p}: task failed ({type(e).__name__}: {str(e)[:300]})", "seconds": 0.0}
                results.append(r)
                bar.update(1)
                say(r)
    except BaseException:
        for f in futures:
            f.cancel()
        raise
    finally:
        bar.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    _make_out(out)
    rows = rows_from_results(results)
    counts = {"done": 0, "skipped": 0, "failed": 0} | ({"missing": 0} if report_only else {})
    for r in results:
        for rec in (r.get("brdf") or []) + ([r["cdf"]] if r.get("cdf") else []):
            counts[rec.get("status", "failed")] = counts.get(rec.get("status", "failed"), 0) + 1
        if r.get("error") and not r.get("brdf"):
            counts["failed"] += 1
    clock.emit("report", f"writing {', '.join(REPORT_FILES)}")
    report = BatchReport(rows, wall_s=time.perf_counter() - t0, counts=counts, workers=n_workers)
    with OutputSet() as outputs:
        report.to_csv(outputs.stage(out / REPORT_FILES[0]))
        outputs.write_text(out / REPORT_FILES[1], report.to_markdown())
        plot_coefficients(rows, out / REPORT_FILES[2], outputs=outputs)
        outputs.commit()
    report.wall_s = time.perf_counter() - t0
    return report


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def _make_out(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(out, f"cannot create folder ({e.strerror or e})", "--out") from None


def material_status(path, options: BatchOptions, out, sha: str):
    """``(result, complete)``: the task result of ``path`` made from its manifests alone (outputs
    done: ``"skipped"`` with their records; not done: ``"missing"``), and whether every output
    is done (then the material is not submitted)."""
    from .keys import brdf_key, cdf_key
    from .tasks import brdf_name, cdf_name, material_dir, read_done

    folder = material_dir(out, path)
    res = {"input": os.fspath(path), "name": Path(path).stem, "sha256": sha, "brdf": [], "cdf": None,
           "error": None, "seconds": 0.0, "worker": None}
    complete = True
    for bo in options.brdf_options():
        key = brdf_key(sha, bo, options.sampler)
        d = read_done(folder / brdf_name(bo, key), key)
        rec = {"key": key, "file": brdf_name(bo, key), "tol": bo.tol}
        if d is None:
            complete = False
            res["brdf"].append(dict(rec, status="missing"))
        else:
            res["brdf"].append(dict(d.get("record", {}), status="skipped", **rec))
    if options.cdf is not None:
        key = cdf_key(sha, options.cdf)
        d = read_done(folder / cdf_name(key), key)
        rec = {"key": key, "file": cdf_name(key)}
        if d is None:
            complete = False
            res["cdf"] = dict(rec, status="missing")
        else:
            res["cdf"] = dict(d.get("record", {}), status="skipped", **rec)
    return res, complete


def _options_tag(options: BatchOptions) -> str:
    import hashlib

    return hashlib.sha256(repr(options).encode()).hexdigest()[:8]


def _one_line(r: dict) -> str:
    if r.get("error"):
        return f"{r['name']}: FAILED: {r['error']}"
    parts = []
    for rec in r.get("brdf") or []:
        if rec.get("status") == "failed":
            parts.append(f"tol {rec.get('tol'):g}: FAILED: {rec.get('error')}")
        else:
            parts.append(f"tol {rec.get('tol'):g}: {rec.get('coefficients')} coefficients "
                         f"({'guaranteed' if rec.get('guaranteed') else 'NOT guaranteed'}, {rec.get('status')})")
    c = r.get("cdf")
    if c:
        parts.append("CDF FAILED: " + str(c.get("error")) if c.get("status") == "failed"
                     else f"CDF {c.get('rows_rational')}/{c.get('rows')} rows rational ({c.get('status')})")
    return f"{r['name']}: " + "; ".join(parts) + f" [{r.get('seconds', 0.0):.1f} s]"
