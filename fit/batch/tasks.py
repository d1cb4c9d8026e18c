"""One material of a batch, as one task (:func:`run_material`): load the measured file once,
fit the BRDF at every tolerance (:func:`fit.rational.brdf_fit.fit_brdf`) and the inverse CDFs
(:func:`fit.sampling.cdf_file.fit_cdf`), with the options and defaults of ``rbrdf-fit brdf``
and ``rbrdf-fit cdf``, and write each output with its manifest.

Outputs of the material ``STEM`` (the input's file name without its suffix) under the batch's
output folder ``OUT``::

    OUT/STEM/brdf-tol0.05-<key>.json            rbrdf-rational coefficient file (with the fit's
                                                own inverse CDFs, as rbrdf-fit brdf stores them)
    OUT/STEM/brdf-tol0.05-<key>.manifest.json   what made it and what it measured
    OUT/STEM/cdf-<key>.json                     rbrdf-cdf file
    OUT/STEM/cdf-<key>.manifest.json

``<key>``: :func:`fit.batch.keys.output_key` (input content hash + options). An output is
*done* when its manifest names the same key and the output file next to it has the sha256 the
manifest records; a done output is skipped and its manifest's ``record`` reported again.
Each output and its manifest are staged together and renamed into place only when both are
complete (:class:`fit.outputs.OutputSet`, output first, manifest last): a task killed at any
moment leaves either nothing, or a whole output without a manifest (redone next time), or both.
Temporary files left by a killed process (hidden ``.NAME.*.part.json``) are removed by the
next task that writes the same output.

A BRDF fit that misses its tolerance on the guaranteed core is written anyway (the file flags
it, as ``rbrdf-fit brdf --allow-infeasible`` does) and reported with ``guaranteed`` False.
Any error of one material (a corrupt file, a failed fit, out of memory) is caught and returned
as the record's one-line ``error``: it never stops the other materials.

Threads: each task runs on one thread (LP solves included, :func:`limit_threads`), so that
N single-threaded workers share N cores without oversubscription.
"""
from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import warnings
from dataclasses import asdict
from pathlib import Path

from ..errors import RbrdfError, display_text
from ..rational.settings import BRDFFitSettings
from .keys import BatchOptions, CdfOptions, SamplerOptions, brdf_key, cdf_key

MANIFEST_FORMAT = "rbrdf-batch-manifest"
MANIFEST_VERSION = 1
#: environment of worker processes: one thread for OpenMP, OpenBLAS, MKL (set before NumPy
#: is imported by the worker; dask's nanny sets the first three by default too)
THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "VECLIB_MAXIMUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1"}

_SETUP_DONE = False


def limit_threads(quiet_banner: bool = False) -> None:
    """One thread per task: HiGHS models of :mod:`fit.rational.lp` get ``threads = 1``; the
    BLAS variables of :data:`THREAD_ENV` are set in this process (they act on libraries not
    yet loaded; workers get them at start). ``quiet_banner``: create one HiGHS model with the
    C-level stdout sent to /dev/null, so that HiGHS's once-per-process banner does not
    interleave with the batch's progress bar (workers only)."""
    global _SETUP_DONE
    if _SETUP_DONE:
        return
    for k, v in THREAD_ENV.items():
        os.environ.setdefault(k, v)
    from ..rational import lp

    lp._HIGHS_OPTIONS.setdefault("threads", 1)
    if quiet_banner and lp._HighsModel is not None:
        with contextlib.suppress(OSError):
            saved = os.dup(1)
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, 1)
                os.close(devnull)
                lp._HighsModel()
            finally:
                os.dup2(saved, 1)
                os.close(saved)
    _SETUP_DONE = True


def material_dir(out, path) -> Path:
    """``OUT/STEM``: the folder of one material's outputs."""
    return Path(out) / Path(path).stem


def brdf_name(options: BRDFFitSettings, key: str) -> str:
    return f"brdf-tol{options.tol:g}-{key}.json"


def cdf_name(key: str) -> str:
    return f"cdf-{key}.json"


def manifest_path(output: Path) -> Path:
    return output.with_name(output.name[:-len(".json")] + ".manifest.json")


def read_done(output: Path, key: str):
    """The manifest of ``output`` if the output is done (manifest readable, same key, output
    present with the recorded sha256), else None."""
    from ..inputs import read_json, sha256_regular
    from ..limits import MAX_JSON_BYTES

    m = manifest_path(output)
    if not m.is_file() or not output.is_file():
        return None
    try:
        d = read_json(m, "batch manifest")
        if not (isinstance(d, dict) and d.get("format") == MANIFEST_FORMAT and d.get("key") == key
                and d.get("output_sha256") == sha256_regular(output, MAX_JSON_BYTES, "batch output")):
            return None
    except (RbrdfError, OSError):
        return None
    return d


def _sweep_temporaries(output: Path) -> None:
    """Remove hidden temporary files of ``output`` and its manifest left by a killed run
    (:func:`fit.atomic_files.temp_in` names them ``.NAME.XXXX.part.json``)."""
    for name in (output.name, manifest_path(output).name):
        for tmp in output.parent.glob(f".{name[:80]}.*.part.json"):
            with contextlib.suppress(OSError):
                tmp.unlink()


def _write(output: Path, save, manifest: dict) -> None:
    """Write ``output`` (``save(tmp_path)``) and its manifest (with the output's sha256),
    both renamed into place only when both are complete."""
    from ..formats.measured import file_sha256
    from ..outputs import OutputSet

    _sweep_temporaries(output)
    with OutputSet(flag=None) as outputs:
        tmp = outputs.stage(output)
        save(tmp)
        manifest = dict(manifest, output=output.name, output_sha256=file_sha256(tmp))
        outputs.write_text(manifest_path(output), json.dumps(manifest, indent=1, allow_nan=False) + "\n")
        outputs.commit()


def brdf_record(fit) -> dict:
    """What the report shows of one :class:`fit.rational.brdf_fit.BRDFFit`: coefficients per
    channel (summed over the pieces) and in total, the guaranteed core's theta_d (deg) and
    whether it is met, the grazing band's status, the largest and the RMS relative error on the
    core (over its pieces and channels, clusters where the relative tolerance applies), the
    fit's seconds."""
    per_channel = [sum(pc.results[c].n_coefficients for pc in fit.pieces if len(pc.results) > c)
                   for c in range(3)]
    core = fit.core_pieces
    errs = [e for pc in core for e in pc.errors]
    n = sum(e["n_points"] for e in errs)
    rms = (sum(e["rms_rel_error"] ** 2 * e["n_points"] for e in errs) / n) ** 0.5 if n else float("nan")
    band = fit.band_pieces
    split = tuple(core[0].theta_h_range_deg) != (0.0, 90.0)
    return {"coefficients": int(fit.n_coefficients), "coefficients_rgb": per_channel,
            "core_theta_d_deg": float(fit.core_theta_d_deg), "core_split_theta_h": bool(split),
            "guaranteed": bool(fit.valid),
            "band": "none" if not band else ("met" if band[0].valid else "best effort"),
            "core_max_rel_error": max((e["max_rel_error"] for e in errs), default=float("nan")),
            "core_rms_rel_error": float(rms), "fit_s": float(fit.time_s),
            "summary": fit.summary()}


def cdf_record(fit, seconds: float) -> dict:
    """What the report shows of one :class:`fit.sampling.cdf_file.CDFFit`: view rows sampled
    with the rational maps (of the table's rows), fallback and its reason, and the per-row
    variance ratio rational / table of the pieces layout's gate (the fitter's measure of the
    sampler's cost in samples; its speed in samples/s needs the renderer:
    ``benchmarks.bench_samplers``)."""
    info = fit.fit_info or {}
    n_rows = int(info.get("n_rows", fit.table.n_v))
    if "verified_rows" in info:
        rational = int(info["verified_rows"])
    else:
        rational = 0 if fit.fallback else n_rows
    ratios = sorted(r["variance"]["ratio"] for r in info.get("rows", []) if r.get("ok") and "variance" in r)
    med = (ratios[len(ratios) // 2] if len(ratios) % 2 else 0.5 * (ratios[len(ratios) // 2 - 1]
                                                                  + ratios[len(ratios) // 2])) if ratios else None
    return {"layout": fit.layout, "rows_rational": rational, "rows": n_rows, "fallback": bool(fit.fallback),
            "reason": fit.reason, "variance_ratio_median": med,
            "variance_ratio_max": ratios[-1] if ratios else None, "cdf_s": float(seconds)}


def _error_text(e: BaseException) -> str:
    if isinstance(e, RbrdfError):
        return display_text(str(e))
    if isinstance(e, MemoryError):
        return "out of memory"
    return display_text(f"{type(e).__name__}: {e}")[:500]


def run_material(path, options: BatchOptions, out, input_sha256: str | None = None) -> dict:
    """Fit one material (every tolerance of ``options``, and its CDF unless ``options.cdf`` is
    None) into ``material_dir(out, path)``; outputs already done are skipped. ``input_sha256``:
    the hash the client computed; a file whose bytes changed since is a failure of this
    material.

    Returns ``{"input", "name", "sha256", "brdf": [record per tolerance], "cdf": record or
    None, "error", "seconds", "worker"}``; every record has ``"status"`` (``"done"``,
    ``"skipped"`` or ``"failed"``), ``"key"``, ``"file"`` and, unless failed, the metrics of
    :func:`brdf_record` / :func:`cdf_record`; ``"error"`` is the one-line reason of a material
    that could not be loaded (then no output was attempted). Never raises for a problem of the
    material (only ``KeyboardInterrupt`` and ``SystemExit`` pass)."""
    from ..formats import check_measured_file
    from ..inputs import sha256_regular

    t0 = time.perf_counter()
    in_worker = _in_dask_worker()
    limit_threads(quiet_banner=in_worker)
    path = Path(path)
    result = {"input": os.fspath(path), "name": path.stem, "sha256": input_sha256, "brdf": [], "cdf": None,
              "error": None, "seconds": 0.0, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    with warnings.catch_warnings(), _errstate():
        warnings.simplefilter("ignore")
        try:
            # the bytes this task reads (the client's hash may be older), checked before they are read
            sha = sha256_regular(path, check_measured_file(path), "measured file")
            if input_sha256 and sha != input_sha256:
                raise RbrdfError(f"{display_text(path)}: the file changed since the batch started")
            result["sha256"] = sha
            folder = material_dir(out, path)
            todo = []
            for bo in options.brdf_options():
                key = brdf_key(sha, bo, options.sampler)
                target = folder / brdf_name(bo, key)
                done = read_done(target, key)
                rec = {"status": "pending", "key": key, "file": target.name, "tol": bo.tol}
                if done is not None:
                    rec.update(done.get("record", {}), status="skipped")
                else:
                    todo.append((bo, key, target, rec))
                result["brdf"].append(rec)
            cdf_todo = None
            if options.cdf is not None:
                key = cdf_key(sha, options.cdf)
                target = folder / cdf_name(key)
                done = read_done(target, key)
                rec = {"status": "pending", "key": key, "file": target.name}
                if done is not None:
                    rec.update(done.get("record", {}), status="skipped")
                else:
                    cdf_todo = (key, target, rec)
                result["cdf"] = rec
            if not todo and cdf_todo is None:
                return result
            brdf = _load(path, options.cdf.incident if options.cdf is not None else "view")
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as e:       # noqa: BLE001 - one material's failure is reported, never raised
            result["error"] = _error_text(e)
            for rec in result["brdf"] + ([result["cdf"]] if result["cdf"] else []):
                if rec["status"] != "skipped":
                    rec.update(status="failed", error=result["error"])
            result["seconds"] = time.perf_counter() - t0
            return result
        src = {"path": os.fspath(path), "file": path.name, "sha256": sha}
        for bo, key, target, rec in todo:
            _run_output(rec, lambda bo=bo, key=key, target=target: _fit_brdf(brdf, path, bo, key, target, src,
                                                                            options.sampler))
        if cdf_todo is not None:
            key, target, rec = cdf_todo
            _run_output(rec, lambda: _fit_cdf(brdf, path, options.cdf, key, target, src))
    result["seconds"] = time.perf_counter() - t0
    return result


def _run_output(rec: dict, work) -> None:
    try:
        rec.update(work(), status="done")
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as e:           # noqa: BLE001
        rec.update(status="failed", error=_error_text(e))


def _load(path: Path, incident: str):
    from ..errors import BRDFFileError
    from ..formats import load_measured

    try:
        return load_measured(path, incident=incident)
    except ValueError as e:
        if isinstance(e, BRDFFileError):
            raise
        raise BRDFFileError(path, str(e)) from None


def _manifest(kind: str, key: str, src: dict, options: dict, record: dict, seconds: float) -> dict:
    return {"format": MANIFEST_FORMAT, "version": MANIFEST_VERSION, "kind": kind, "key": key, "input": src,
            "options": options, "record": record, "seconds": seconds,
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "worker": f"{socket.gethostname()}:{os.getpid()}"}


def _fit_brdf(brdf, path: Path, bo: BRDFFitSettings, key: str, target: Path, src: dict,
              sampler: SamplerOptions | None = None) -> dict:
    from ..errors import BRDFFileError
    from ..rational.brdf_fit import fit_brdf

    t = time.perf_counter()
    try:
        fit = fit_brdf(brdf, bo, source_file=path.name)
    except ValueError as e:
        raise BRDFFileError(path, str(e)) from None
    record = brdf_record(fit)
    if sampler is not None:
        record.update(_attach_sampler(fit.model, sampler))
    options = bo.get_params() if sampler is None else {**bo.get_params(), "sampler": asdict(sampler)}
    _write(target, fit.save, _manifest("brdf", key, src, options, record, time.perf_counter() - t))
    return record


def _attach_sampler(model, sampler: SamplerOptions) -> dict:
    """Store the fit's own inverse CDFs in ``model`` (:func:`fit.sampling.model_sampler.embed_sampler`,
    as ``rbrdf-fit brdf``); the record's ``sampler`` (``"rational"``, ``"table"`` or ``"none"``:
    a fit with nothing vouched to sample is written without one), ``sampler_reason`` and
    ``sampler_s``."""
    from ..sampling.model_sampler import embed_sampler

    t = time.perf_counter()
    try:
        cdf = embed_sampler(model, time_limit_s=sampler.time_limit_s)
    except ValueError as e:
        return {"sampler": "none", "sampler_reason": display_text(e), "sampler_s": time.perf_counter() - t}
    return {"sampler": "table" if cdf.fallback else "rational", "sampler_reason": cdf.reason,
            "sampler_rows_rational": int((cdf.fit_info or {}).get("verified_rows", 0 if cdf.fallback else cdf.table.n_v)),
            "sampler_rows": int(cdf.table.n_v), "sampler_s": time.perf_counter() - t}


def _fit_cdf(brdf, path: Path, co: CdfOptions, key: str, target: Path, src: dict) -> dict:
    from ..sampling.cdf_file import fit_cdf

    t = time.perf_counter()
    source = {"file": src["file"], "sha256": src["sha256"]}
    if path.suffix.lower() == ".bsdf":      # as rbrdf-fit cdf records it
        source["incident"] = co.incident
    fit = fit_cdf(brdf.evaluate, name=brdf.name, layout=co.layout, refinements=co.refinements, source=source,
                  table_params={"n_v": co.n_v, "n_t": co.n_t, "n_p": co.n_p, "eps": co.eps},
                  time_limit_s=co.time_limit_s)
    seconds = time.perf_counter() - t
    record = cdf_record(fit, seconds)
    _write(target, fit.save, _manifest("cdf", key, src, asdict(co), record, seconds))
    return record


def _errstate():
    import numpy as np

    return np.errstate(all="ignore")


def _in_dask_worker() -> bool:
    try:
        from distributed import get_worker

        get_worker()
        return True
    except Exception:                      # noqa: BLE001 - not in a worker (or no distributed)
        return False
