"""The `distributed:` part of a spec: where a distributed engine's workers run the runs. It belongs to the backends
that use it (Dask, dask-jobqueue), which receive it alone, never the whole campaign spec; the spec's schema includes
it."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


def walltime_seconds(text: str) -> int:
    """A walltime in Slurm's forms (M, M:S, H:M:S, D-H, D-H:M, D-H:M:S) in seconds; ValueError otherwise."""
    days, dash, clock = text.strip().rpartition("-")
    parts = clock.split(":")
    if (dash and not days.isdigit()) or not all(p.isdigit() for p in parts) or len(parts) > 3:
        raise ValueError(f"walltime {text!r} is not one of M, M:S, H:M:S, D-H, D-H:M, D-H:M:S")
    values = [int(p) for p in parts]
    if dash:  # D-H, D-H:M, D-H:M:S
        h, m, sec = (values + [0, 0])[:3]
    elif len(values) == 3:
        h, m, sec = values
    elif len(values) == 2:  # M:S
        h, m, sec = 0, *values
    else:  # M
        h, m, sec = 0, values[0], 0
    return int(days or 0) * 86400 + h * 3600 + m * 60 + sec


class DistributedSpec(BaseModel):
    """Runs executed by a distributed engine's workers instead of this machine's lanes: a Dask scheduler
    someone started (`address`), or Dask workers slamrun submits as batch jobs (`cluster`: Slurm, PBS, SGE,
    LSF through dask-jobqueue) and cancels when the campaign ends."""

    model_config = ConfigDict(extra="forbid")

    engine: Literal["dask"] = Field("dask", description="The engine: a Dask distributed cluster.")
    address: str | None = Field(
        None,
        description="Scheduler address (tcp://host:8786), or 'local' for `lanes` worker processes on this "
        "machine (loopback only; for trying it out). Results and view cache must be on a filesystem every "
        "worker sees at the same path.",
    )
    cluster: Literal["slurm", "pbs", "sge", "lsf"] | None = Field(
        None, description="Submit the workers as batch jobs of this scheduler (dask-jobqueue), instead of `address`."
    )
    queue: str | None = Field(None, description="Partition (Slurm) or queue the worker jobs go to.")
    account: str | None = Field(None, description="Account the jobs are charged to.")
    cores: int = Field(2, ge=1, description="CPU cores per worker job; a worker runs one run at a time.")
    memory: str = Field("8GB", pattern=r"^\d+(\.\d+)?\s*[KMGT]i?B$", description="Memory per worker job, e.g. 8GB.")
    walltime: str = Field("12:00:00", description="Walltime of one worker job; longer than timeout_s + stop_grace_s.")
    job_directives: list[str] = Field(
        default_factory=list, description="Extra batch directives, e.g. ['--gres=gpu:1'] (Slurm: #SBATCH lines)."
    )
    job_prologue: list[str] = Field(
        default_factory=list, description="Shell lines a job runs before its worker (module load, source a venv)."
    )
    python: str | None = Field(None, description="The workers' Python with slamrun installed (default: this one).")
    interface: str | None = Field(
        None, description="Network interface the scheduler and workers listen on (e.g. ib0; lo on one machine)."
    )
    min_workers: int = Field(1, ge=1, description="Worker jobs kept alive (a lost one is replaced).")
    max_workers: int | None = Field(None, ge=1, description="Most worker jobs at once (default: lanes).")
    worker_wait_s: float = Field(
        600.0, gt=0, description="How long to wait for the first worker job to start before giving up (with why)."
    )
    log_directory: Path | None = Field(None, description="The jobs' stdout/stderr (default: results/jobs).")

    @model_validator(mode="after")
    def _address_or_cluster(self) -> DistributedSpec:
        if (self.address is None) == (self.cluster is None):
            raise ValueError(
                "give either address (a running Dask scheduler, or 'local') or cluster (slurm, pbs, sge, lsf)"
            )
        if self.cluster is not None:
            walltime_seconds(self.walltime)
        if self.max_workers is not None and self.max_workers < self.min_workers:
            raise ValueError(f"max_workers {self.max_workers} is below min_workers {self.min_workers}")
        return self

    @property
    def walltime_s(self) -> int:
        return walltime_seconds(self.walltime)
