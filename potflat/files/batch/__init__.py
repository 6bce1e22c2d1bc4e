"""Batches: many scans through all stages, validated up front, resumable, in parallel.

:mod:`.config` reads and validates the batch file, :mod:`.manifest` records what each scan
folder holds, :mod:`.execution` runs the scans (local processes or a Dask cluster) and
writes the summary, :mod:`.report` the HTML report.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {**dict.fromkeys(("Batch", "BatchFileError", "ScanJob", "load_batch"), ".config"),
                                      **dict.fromkeys(("BatchSummary", "ScanReport", "run_batch"), ".execution")})
__all__ = ["Batch", "BatchFileError", "BatchSummary", "ScanJob", "ScanReport", "load_batch", "run_batch"]
