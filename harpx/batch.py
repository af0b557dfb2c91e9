"""Track a cohort of subjects in parallel with dask.distributed, resumably.

:func:`track_many` treats each input archive (``tagged/1`` or ``phase/1`` NetCDF) as one
subject: it builds the subject's :class:`~harpx.mechanics.body.Body` with a user function,
tracks it with :func:`harpx.tracking.track.track` on a dask cluster and writes one
``tracked/1`` archive per subject with the atomic :func:`harpx.io.netcdf.to_netcdf`.

Nothing is lost when a cohort is interrupted or a subject fails:

- archives are only ever complete (atomic writes), so a killed run leaves finished subjects
  finished and the others absent;
- a re-run skips every subject whose archive opens cleanly and was made from the same input
  with the same settings and body (SHA-256 of the input and of the body built, fingerprint
  of the body factory and tracking settings), and redoes missing, corrupt or stale ones;
- a failing subject does not stop the others: all are run, then one :class:`CohortError`
  lists the failures.

dask.distributed is an optional dependency (``pip install harpx[distributed]``), imported
only when there is work to do.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import inspect
import json
import numbers
import os
import pickle
import uuid
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from harpx._progress import progress_bar
from harpx._typing import PathLike
from harpx.errors import ArchiveError, HarpxError, SchemaError
from harpx.io.netcdf import open_dataset, to_netcdf
from harpx.schema import newer_schema, validate

__all__ = [
    "CohortError",
    "local_cluster",
    "output_path",
    "settings_fingerprint",
    "track_many",
    "track_subject",
]

#: Suffix of each subject's archive: ``<input stem>_tracked.nc``.
OUTPUT_SUFFIX = "_tracked.nc"
_SOURCE_ATTR = "source_file"
_DIGEST_ATTR = "source_sha256"
_SETTINGS_ATTR = "settings_sha256"
_SETTINGS_TEXT_ATTR = "settings_fingerprint"
_BODY_ATTR = "body_sha256"
#: Body attributes that say what is tracked (the rest is derived from them).
_BODY_FIELDS: tuple[str, ...] = ("element", "volumetric", "regions", "boundaries", "fibers_qp")
_BODY_FIELDS += ("t_max", "growth_tensor", "material", "active")


class CohortError(HarpxError):
    """Some subjects of a cohort failed; the others were written.

    Parameters
    ----------
    message : str
        Summary naming every failed subject.
    failures : dict of pathlib.Path to BaseException
        Input archive → the error it raised.
    outputs : list of pathlib.Path
        Output archive of every subject, in input order (those of failed subjects do not
        exist).
    """

    def __init__(
        self, message: str, failures: Mapping[Path, BaseException], outputs: list[Path]
    ) -> None:
        self.failures: dict[Path, BaseException] = dict(failures)
        self.outputs: list[Path] = list(outputs)
        super().__init__(message)


def output_path(path: PathLike, output_dir: PathLike) -> Path:
    """Archive that :func:`track_many` writes for one input archive.

    Parameters
    ----------
    path : str or os.PathLike
        Input archive.
    output_dir : str or os.PathLike
        Output directory.

    Returns
    -------
    pathlib.Path
        ``output_dir / (stem + "_tracked.nc")``.

    Examples
    --------
    >>> output_path("cohort/s01.nc", "out").as_posix()
    'out/s01_tracked.nc'
    """
    return Path(output_dir) / f"{Path(path).stem}{OUTPUT_SUFFIX}"


def track_many(
    paths: Iterable[PathLike],
    body_factory: Callable[[Any], Any],
    *,
    output_dir: PathLike,
    client: Any = None,
    address: str | None = None,
    n_workers: int = 2,
    track_kwargs: Mapping[str, Any] | None = None,
    overwrite: bool = False,
    progress: bool | None = None,
) -> list[Path]:
    """Track every subject of a cohort on a dask cluster, one archive per subject.

    Parameters
    ----------
    paths : iterable of str or os.PathLike
        Input archives, one per subject: ``tagged/1`` (its phase is extracted with the
        defaults of :func:`harpx.imaging.harp.extract_phase`) or ``phase/1`` NetCDF files.
        File stems must be unique.
    body_factory : callable
        ``body_factory(ds) -> Body`` for the subject's dataset (mesh in mm, in the image
        frame). It runs on the workers, so it must be picklable: a top-level function of an
        importable module, or a :func:`functools.partial` of one.
    output_dir : str or os.PathLike
        Directory of the output archives ``<stem>_tracked.nc`` (created if needed).
    client : distributed.Client, optional
        An existing client to run on (left open).
    address : str, optional
        Scheduler address of a running cluster (e.g. ``"tcp://10.0.0.5:8786"``); a client
        is opened for this call and closed after it.
    n_workers : int, default 2
        Worker processes of the local cluster started when neither ``client`` nor
        ``address`` is given (:func:`local_cluster`: one thread and one BLAS/MKL thread
        each). The cluster is closed at the end.
    track_kwargs : mapping, optional
        Keyword arguments of :func:`harpx.tracking.track.track` (e.g. ``epsilon``,
        ``method``), the same for every subject.
    overwrite : bool, default False
        Redo every subject. By default a subject is skipped when its archive opens cleanly,
        is a valid ``tracked/1`` dataset and records the SHA-256 of the current input, the
        fingerprint of ``body_factory`` and ``track_kwargs`` (:func:`settings_fingerprint`)
        and the SHA-256 of the body (mesh, element, regions, fibres, material) the factory
        builds now: other settings, or a body changed by anything the factory reads (a
        module constant, a helper, a mesh file), mean the subject is redone.
    progress : bool or None, default None
        Progress bar over subjects; None: shown in terminals and notebooks once the call
        has run a few seconds (:mod:`harpx._progress`).

    Returns
    -------
    list of pathlib.Path
        The output archive of each subject, in input order.

    Raises
    ------
    CohortError
        After every other subject is written, if some subjects failed (missing or unreadable
        input, ``body_factory`` or tracking errors, a lost worker); ``err.failures`` maps
        each failed input to its error. Re-running resumes with the failed ones only.
        Subjects that ran out of memory (``MemoryError``, or a worker killed by its nanny)
        are told apart in the message: they need fewer workers or more memory, not a fix
        of their input.
    MemoryError
        If checking an existing archive runs out of memory (it is not taken for an
        incomplete archive and redone). ``KeyboardInterrupt`` stops the call as well, after
        cancelling the subjects still queued.
    ValueError
        If ``paths`` is empty, both ``client`` and ``address`` are given, ``n_workers`` is
        not a whole number ≥ 1, two inputs share a file stem, or a tracking setting in
        ``track_kwargs`` is out of range (checked once, before any work).
    TypeError
        If ``paths`` holds something that is not a path, ``track_kwargs`` has a name
        :func:`~harpx.tracking.track.track` does not take, or ``body_factory`` cannot be
        pickled.
    FileExistsError
        If ``output_dir`` is a file.
    ImportError
        If there is work to do and dask.distributed is not installed.

    Notes
    -----
    The skip decision is made here, before any cluster starts: a cohort that is already
    complete needs no cluster, but calls ``body_factory`` here once per existing archive.
    Each archive records ``source_file`` (input name), ``source_sha256``, ``body_sha256``,
    ``settings_sha256`` and the text it hashes, ``settings_fingerprint`` (an archive
    without ``body_sha256`` is redone). Workers read the inputs and write the outputs
    themselves, so on a remote cluster (``address=``) both paths must name the same files
    on the workers (a shared file system).

    Examples
    --------
    >>> def body_factory(ds):  # doctest: +SKIP
    ...     return Body(cylinder(30.0, 12.0), NeoHookean(c1=1.0, kappa=120.0))
    >>> track_many(sorted(Path("cohort").glob("*.nc")), body_factory,
    ...            output_dir="tracked", track_kwargs={"epsilon": 0.05})  # doctest: +SKIP
    """
    if isinstance(paths, str | bytes | os.PathLike):
        raise TypeError(
            f"paths must be an iterable of input files, got the single path {paths!r} (which "
            f"would be read character by character); pass a list: [{paths!r}]"
        )
    if not isinstance(paths, Iterable):
        raise TypeError(f"paths must be an iterable of input files, got {paths!r}")
    given = list(paths)
    wrong = [p for p in given if not isinstance(p, str | os.PathLike)]
    if wrong:
        raise TypeError(
            f"paths holds {len(wrong)} entries that are not file paths (e.g. {wrong[0]!r}); "
            "pass str or os.PathLike"
        )
    if not given:
        raise ValueError("paths is empty: there is no subject to track (did a glob match no file?)")
    inputs = [Path(p) for p in given]
    kwargs = dict(track_kwargs or {})
    _check_arguments(inputs, body_factory, client, address, n_workers, kwargs)
    out_dir = Path(output_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise FileExistsError(
            f"output_dir {str(out_dir)!r} is a file, not a folder; choose a folder for the "
            "tracked archives"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    outputs = [output_path(p, out_dir) for p in inputs]
    settings = settings_fingerprint(body_factory, kwargs)

    failures: dict[int, BaseException] = {}
    todo: list[tuple[int, str]] = []  # (subject index, input digest)
    for i, (source, target) in enumerate(zip(inputs, outputs, strict=True)):
        try:
            digest = _sha256(source)
        except OSError as exc:
            failures[i] = ArchiveError(f"cannot read input {str(source)!r}: {exc}")
            continue
        if overwrite or not _is_complete(target, digest, settings[0], source, body_factory):
            todo.append((i, digest))

    done = len(inputs) - len(todo) - len(failures)
    with progress_bar(
        total=len(inputs), initial=done, progress=progress, desc="subjects", unit="subject"
    ) as bar:
        bar.update(len(failures))
        if todo:
            _run(
                todo,
                inputs,
                outputs,
                body_factory,
                kwargs,
                client,
                address,
                n_workers,
                failures,
                bar,
                settings,
            )
    if failures:
        raise _cohort_error(inputs, outputs, failures, out_dir)
    return outputs


# --- the work of one subject (runs on a worker) -------------------------------------------


def track_subject(
    source: PathLike,
    target: PathLike,
    body_factory: Callable[[Any], Any],
    track_kwargs: Mapping[str, Any] | None = None,
    digest: str | None = None,
    settings: tuple[str, str] | None = None,
) -> Path:
    """Track one subject and write its archive (the task :func:`track_many` distributes).

    Parameters
    ----------
    source : str or os.PathLike
        Input ``tagged/1`` or ``phase/1`` archive.
    target : str or os.PathLike
        Output ``tracked/1`` archive, written atomically.
    body_factory : callable
        ``body_factory(ds) -> Body``.
    track_kwargs : mapping, optional
        Keyword arguments of :func:`harpx.tracking.track.track`.
    digest : str, optional
        SHA-256 of ``source`` recorded in the archive (computed if None).
    settings : tuple of str, optional
        :func:`settings_fingerprint` of ``body_factory`` and ``track_kwargs`` recorded in
        the archive (computed if None).

    Returns
    -------
    pathlib.Path
        ``target``.

    Raises
    ------
    SchemaError
        If ``source`` is not a ``tagged/1`` or ``phase/1`` archive.
    """
    from harpx.tracking.track import track

    source = Path(source)
    ds = open_dataset(source)
    kind = ds.attrs.get("harpx_schema")
    if kind not in ("tagged/1", "phase/1"):
        newer = newer_schema(kind)
        raise SchemaError(
            f"input {str(source)!r} has harpx_schema {kind!r}; track_many needs 'tagged/1' "
            "or 'phase/1' archives" + (f" ({newer})" if newer else "")
        )
    body = body_factory(ds)
    body_digest = _body_digest(body)  # before tracking, as the resume check builds it
    tracked = track(ds, body, **dict(track_kwargs or {}))
    tracked.attrs[_SOURCE_ATTR] = source.name
    tracked.attrs[_DIGEST_ATTR] = digest if digest is not None else _sha256(source)
    sha, text = settings or settings_fingerprint(body_factory, dict(track_kwargs or {}))
    tracked.attrs[_SETTINGS_ATTR] = sha
    tracked.attrs[_SETTINGS_TEXT_ATTR] = text
    tracked.attrs[_BODY_ATTR] = body_digest
    return to_netcdf(tracked, target)


def settings_fingerprint(
    body_factory: Callable[[Any], Any], track_kwargs: Mapping[str, Any] | None = None
) -> tuple[str, str]:
    """Fingerprint of how a cohort is tracked: the body factory and the tracking settings.

    Parameters
    ----------
    body_factory : callable
        ``body_factory(ds) -> Body``. A function is described by its module, name, source
        code and default arguments; a :func:`functools.partial` by its function and
        arguments; another callable by its type and fields (dataclasses) or ``repr``.
        Module constants, helper functions and files the factory reads are not part of
        this description: :func:`track_many` compares the body the factory builds as
        well (``body_sha256``).
    track_kwargs : mapping, optional
        Keyword arguments of :func:`harpx.tracking.track.track`. Arrays are described by
        their dtype, shape and a SHA-256 of their bytes, dataclasses (e.g. ``Fixed``) by
        their fields.

    Returns
    -------
    sha256 : str
        Hex digest of ``text``.
    text : str
        The JSON description that is hashed (recorded in each archive, to see what
        changed).

    Examples
    --------
    >>> def body(ds):
    ...     return None
    >>> a, _ = settings_fingerprint(body, {"epsilon": 0.05})
    >>> b, _ = settings_fingerprint(body, {"epsilon": 0.1})
    >>> a == b
    False
    """
    description = {
        "body_factory": _describe_callable(body_factory),
        "track_kwargs": {str(k): _describe(v) for k, v in sorted(dict(track_kwargs or {}).items())},
    }
    text = json.dumps(description, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest(), text


def _body_digest(body: Any) -> str:
    """SHA-256 of what a built body is: type, mesh nodes and cells, :data:`_BODY_FIELDS`."""
    mesh = getattr(body, "mesh", None)
    description = {
        "type": _describe_object(type(body)),
        "mesh": [_describe_object(type(mesh)), *(_describe(getattr(mesh, a, None)) for a in "pt")],
        **{name: _describe_object(getattr(body, name, None)) for name in _BODY_FIELDS},
    }
    return hashlib.sha256(json.dumps(description, sort_keys=True).encode()).hexdigest()


def _describe_object(value: Any) -> Any:
    """:func:`_describe`; a class by name, a plain object (a material) by its attributes."""
    if isinstance(value, type):
        return f"{value.__module__}.{value.__qualname__}"
    if dataclasses.is_dataclass(value) or callable(value) or not hasattr(value, "__dict__"):
        return _describe(value)
    attrs = {str(k): _describe(v) for k, v in sorted(vars(value).items())}
    return {"type": _describe_object(type(value)), **attrs}


def _describe_callable(fn: Any) -> Any:
    if isinstance(fn, functools.partial):
        return {
            "partial": _describe_callable(fn.func),
            "args": [_describe(a) for a in fn.args],
            "keywords": {k: _describe(v) for k, v in sorted(fn.keywords.items())},
        }
    if inspect.isfunction(fn) or inspect.ismethod(fn):
        try:
            source = inspect.getsource(fn)
        except (OSError, TypeError):  # defined interactively: hash the compiled code
            code = fn.__code__
            source = code.co_code.hex() + repr(code.co_consts)
        return {
            "function": f"{fn.__module__}.{fn.__qualname__}",
            "source_sha256": hashlib.sha256(source.encode()).hexdigest(),
            "defaults": _describe(fn.__defaults__),
            "kwdefaults": _describe(getattr(fn, "__kwdefaults__", None)),
        }
    return {"callable": f"{type(fn).__module__}.{type(fn).__qualname__}", "value": _describe(fn)}


def _describe(value: Any) -> Any:
    """A JSON-able description that changes whenever the value does."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, np.ndarray | np.generic):
        data = np.ascontiguousarray(value)
        return {
            "array": str(data.dtype),
            "shape": list(data.shape),
            "sha256": hashlib.sha256(data.tobytes()).hexdigest(),
        }
    if isinstance(value, list | tuple):
        return [_describe(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _describe(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: _describe(getattr(value, f.name)) for f in dataclasses.fields(value)}
        return {"type": f"{type(value).__module__}.{type(value).__qualname__}", **fields}
    if callable(value):
        return _describe_callable(value)
    text = repr(value)
    if " at 0x" in text:  # a default repr names a memory address: describe the pickle instead
        try:
            import cloudpickle

            return {"pickle_sha256": hashlib.sha256(cloudpickle.dumps(value)).hexdigest()}
        except Exception:
            pass
    return {"repr": text}


def local_cluster(n_workers: int = 2) -> Any:
    """A local dask cluster tuned for tracking: processes with one thread each.

    Parameters
    ----------
    n_workers : int, default 2
        Worker processes (one per core is a good choice).

    Returns
    -------
    distributed.LocalCluster
        Scheduler, workers and dashboard (if bokeh is installed) listen on the loopback
        interface only (127.0.0.1, a free port), never on the network. Close it (or use it
        as a context manager) when done.

    Raises
    ------
    ValueError
        If ``n_workers`` is below 1.
    ImportError
        If dask.distributed is not installed (the message says how to install it).

    Notes
    -----
    Workers get ``OMP_NUM_THREADS = MKL_NUM_THREADS = OPENBLAS_NUM_THREADS = 1`` (one BLAS,
    PARDISO and pyFFTW thread per process, so workers do not oversubscribe the cores) but
    not dask's default ``MALLOC_TRIM_THRESHOLD_=65536``: with it, glibc returns memory to
    the system after every large temporary, which doubles the CPU time of tracking a
    subject (``benchmarks/results/tracking_defaults.md``, ``benchmarks/bench_batch.py``).
    Use this cluster's settings for a cluster started elsewhere too.
    """
    (LocalCluster,) = _distributed("local_cluster", "LocalCluster")
    import dask

    if int(n_workers) < 1:
        raise ValueError(f"n_workers={n_workers!r} must be at least 1")
    environ = {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
        return LocalCluster(
            n_workers=int(n_workers),
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
        )


# --- helpers ------------------------------------------------------------------------------


def _distributed(caller: str, *names: str) -> tuple[Any, ...]:
    """Names from dask.distributed, with an install hint if it is missing."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(
            f"{caller} needs dask.distributed; install it with `pip install "
            "harpx[distributed]` (or `pip install distributed`)"
        ) from exc
    return tuple(getattr(distributed, name) for name in names)


def _check_arguments(
    inputs: list[Path],
    body_factory: Callable[[Any], Any],
    client: Any,
    address: str | None,
    n_workers: int,
    kwargs: Mapping[str, Any],
) -> None:
    if client is not None and address is not None:
        raise ValueError("pass either client= or address=, not both")
    whole = isinstance(n_workers, numbers.Integral) and not isinstance(n_workers, bool)
    if client is None and address is None and not (whole and n_workers >= 1):
        raise ValueError(f"n_workers={n_workers!r} must be a whole number of processes, at least 1")
    stems: dict[str, list[str]] = {}
    for p in inputs:
        stems.setdefault(p.stem, []).append(str(p))
    clashes = {s: v for s, v in stems.items() if len(v) > 1}
    if clashes:
        raise ValueError(
            f"inputs share file stems, so their outputs would collide: {clashes!r}; rename "
            "them or track them into different output_dir"
        )
    if not callable(body_factory):
        raise TypeError(f"body_factory must be callable, got {type(body_factory).__name__!r}")
    from harpx.tracking.settings import TrackingSettings
    from harpx.tracking.track import track

    params = inspect.signature(track).parameters
    allowed = [n for n, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY]
    allowed += [f.name for f in dataclasses.fields(TrackingSettings)]
    unknown = sorted(set(kwargs) - set(allowed))
    if unknown:
        raise TypeError(
            f"track_kwargs has {unknown!r}, which harpx.tracking.track.track does not take; "
            f"allowed: {allowed!r}"
        )
    names = {f.name for f in dataclasses.fields(TrackingSettings)}
    try:  # values out of range fail here, once, not once per subject on the workers
        TrackingSettings.build(
            kwargs.get("settings"), **{k: v for k, v in kwargs.items() if k in names}
        )
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"track_kwargs: {exc}") from exc
    try:
        import cloudpickle

        cloudpickle.dumps(body_factory)
    except ImportError:  # pragma: no cover - cloudpickle comes with dask
        pickle.dumps(body_factory)
    except Exception as exc:
        raise TypeError(
            f"body_factory {body_factory!r} cannot be pickled for the dask workers "
            f"({type(exc).__name__}: {exc}); define it as a top-level function of an "
            "importable module"
        ) from exc


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _is_complete(target: Path, digest: str, settings: str, source: Path, factory: Any) -> bool:
    """Whether ``target`` is a readable, valid tracked/1 archive made from this input,
    these settings and the body ``factory`` builds now (from the input as
    :func:`track_subject` reads it; last, and a failing factory means redo).

    The archive is opened lazily and its variables are streamed chunk by chunk (a
    truncated file fails while reading), so the check never holds more than one chunk in
    memory, whatever sizes the file declares.
    """
    if not target.is_file():
        return False
    try:
        with open_dataset(target, chunks={}) as ds:
            recorded = ds.attrs.get(_BODY_ATTR)
            if (ds.attrs.get(_DIGEST_ATTR), ds.attrs.get(_SETTINGS_ATTR)) != (digest, settings):
                return False
            validate(ds, "tracked")
            for var in ds.variables.values():
                if var.chunks is not None:  # read every block, one at a time
                    for block in var.data.to_delayed().ravel():
                        block.compute(scheduler="synchronous")
        with open_dataset(source) as subject:  # closed again: the input stays unlocked
            return bool(_body_digest(factory(subject)) == recorded)
    except MemoryError as exc:  # not a sign of a bad archive: redoing it would not help
        raise MemoryError(
            f"ran out of memory while checking the existing archive {str(target)!r}; free "
            "memory, or pass overwrite=True to redo the subject without checking it"
        ) from exc
    except Exception:  # unreadable, invalid or truncated (a block fails to read): redo it
        return False
    return True


def _run(
    todo: list[tuple[int, str]],
    inputs: list[Path],
    outputs: list[Path],
    body_factory: Callable[[Any], Any],
    kwargs: Mapping[str, Any],
    client: Any,
    address: str | None,
    n_workers: int,
    failures: dict[int, BaseException],
    bar: Any,
    settings: tuple[str, str],
) -> None:
    Client, as_completed = _distributed("track_many", "Client", "as_completed")
    owned: list[Any] = []  # cluster/client opened here, closed in `finally`
    futures: dict[Any, int] = {}
    try:
        if client is None:
            if address is not None:
                client = Client(address)
            else:
                cluster = local_cluster(n_workers)
                owned.append(cluster)
                client = Client(cluster)
            owned.insert(0, client)
        futures = {
            client.submit(
                track_subject,
                str(inputs[i]),
                str(outputs[i]),
                body_factory,
                kwargs,
                digest,
                settings,
                key=f"harpx-track-{inputs[i].stem}-{uuid.uuid4().hex}",
                pure=False,
            ): i
            for i, digest in todo
        }
        for future in as_completed(futures):
            i = futures[future]
            try:
                future.result()
            except Exception as exc:  # one subject's failure never stops the others
                failures[i] = exc
            bar.update(1)
    except BaseException:  # e.g. KeyboardInterrupt here: stop the subjects still queued
        if client is not None and not owned:  # a cluster opened here is closed below
            with contextlib.suppress(Exception):
                client.cancel([f for f in futures if not f.done()])
        raise
    finally:
        for thing in owned:
            thing.close()


def _out_of_memory(exc: BaseException) -> bool:
    """Whether a subject failed for lack of memory rather than because of its input."""
    if isinstance(exc, MemoryError):
        return True
    # dask.distributed.KilledWorker: the worker died (most often killed for its memory)
    return type(exc).__name__ == "KilledWorker"


def _cohort_error(
    inputs: list[Path], outputs: list[Path], failures: Mapping[int, BaseException], out: Path
) -> CohortError:
    lines = []
    for i in sorted(failures):
        exc = failures[i]
        first = (str(exc).strip().splitlines() or [""])[0]
        lines.append(f"  {str(inputs[i])!r}: {type(exc).__name__}: {first}")
    n_ok = len(inputs) - len(failures)
    memory = sorted(i for i in failures if _out_of_memory(failures[i]))
    advice = "\nfix these subjects and run track_many again: finished subjects are skipped"
    if memory:
        advice = (
            f"\n{len(memory)} of them ran out of memory (MemoryError or a killed worker), "
            "which says nothing about their input: run track_many again with fewer workers "
            "(n_workers=) or on workers with more memory; finished subjects are skipped"
        )
        if len(memory) < len(failures):
            advice += "; fix the other subjects first"
    message = (
        f"{len(failures)} of {len(inputs)} subjects failed; the other {n_ok} archives are in "
        f"{str(out)!r}:\n" + "\n".join(lines) + advice
    )
    return CohortError(message, {inputs[i]: failures[i] for i in failures}, outputs)
