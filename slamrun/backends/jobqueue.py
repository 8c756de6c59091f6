"""Dask workers as batch jobs (Slurm, PBS, SGE, LSF through dask-jobqueue), owned by one campaign.

The campaign machine (a login node) runs the Dask scheduler; each worker is a batch job that runs one run at a
time. Jobs carry a name derived from the results folder, so a campaign that crashed leaves nothing that its next
start does not cancel. Before any job is submitted the job script is checked by the batch system itself where it
can (Slurm's `sbatch --test-only`), so a wrong partition, account or size is an error before any run starts; a
job that then stays queued is reported, with the batch system's reason, after `worker_wait_s`.
"""

from __future__ import annotations

import getpass
import hashlib
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from slamrun.errors import InfraError

if TYPE_CHECKING:
    from slamrun.backends.distributed import DistributedSpec

# per batch system: dask-jobqueue's class, and the commands slamrun needs on this machine
SYSTEMS = {
    "slurm": ("SLURMCluster", ("sbatch", "squeue", "scancel", "sinfo")),
    "pbs": ("PBSCluster", ("qsub", "qstat", "qdel", "qselect")),
    "sge": ("SGECluster", ("qsub", "qstat", "qdel")),
    "lsf": ("LSFCluster", ("bsub", "bjobs", "bkill")),
}
DEATH_TIMEOUT_S = 60  # a worker that cannot reach the scheduler this long exits (its job ends)
REPLACE_WAIT_S = 5  # a job whose worker left (the batch system ended it) is replaced after this long


def job_name(results: Path) -> str:
    """The batch name of a campaign's worker jobs: the same for every start of the same results folder."""
    digest = hashlib.sha256(str(Path(results).resolve()).encode()).hexdigest()[:10]
    return f"slamrun-{digest}"


def _run(argv: list[str], timeout: float = 60) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise InfraError(f"`{' '.join(argv)}` did not answer within {timeout:.0f} s; is the batch system up?") from None


def missing_commands(system: str) -> list[str]:
    return [c for c in SYSTEMS[system][1] if shutil.which(c) is None]


def our_jobs(system: str, name: str) -> list[tuple[str, str, str]]:
    """(job id, state, reason) of this campaign's jobs still known to the batch system (Slurm only: others
    return [])."""
    if system != "slurm":
        return []
    out = _run(["squeue", "-h", "-u", getpass.getuser(), "-n", name, "-o", "%i|%T|%r"])
    return [tuple(line.split("|", 2)) for line in out.stdout.splitlines() if line.count("|") == 2]  # type: ignore[misc]


def cancel_jobs(system: str, name: str) -> None:
    """Cancel every job of this campaign (left by a crashed start, or at the end)."""
    user = getpass.getuser()
    if system == "slurm":
        _run(["scancel", "-u", user, "-n", name])
    elif system == "lsf":
        _run(["bkill", "-u", user, "-J", name, "0"])
    elif system == "sge":
        _run(["qdel", "-u", user, name])
    elif system == "pbs":
        ids = _run(["qselect", "-u", user, "-N", name]).stdout.split()
        if ids:
            _run(["qdel", *ids])


def preflight(d: DistributedSpec) -> None:
    """What can be known before a job is submitted: the batch system's commands, the partition."""
    system = d.cluster
    assert system is not None
    missing = missing_commands(system)
    if missing:
        raise InfraError(
            f"distributed.cluster: {system} needs the batch system's commands on this machine's PATH; missing: "
            f"{', '.join(missing)}. Run the campaign on a login node of the cluster (or install the {system} client)"
        )
    if system == "slurm" and d.queue:
        out = _run(["sinfo", "-h", "-o", "%R"])
        partitions = sorted(set(out.stdout.split()))
        if out.returncode == 0 and d.queue not in partitions:
            raise InfraError(
                f"distributed.queue: Slurm has no partition {d.queue!r} (it has: {', '.join(partitions) or 'none'}); "
                "set queue to one of them"
            )


def make_job_cluster(d: DistributedSpec, results: Path, lanes: int):
    """A dask-jobqueue cluster for `d` (jobs not submitted yet): one worker per job, one run at a time."""
    try:
        import dask_jobqueue
    except ImportError:
        raise InfraError("distributed.cluster needs dask-jobqueue: pip install 'slamrun[cluster]'") from None
    cls = getattr(dask_jobqueue, SYSTEMS[d.cluster][0])
    logs = Path(d.log_directory or Path(results) / "jobs")
    logs.mkdir(parents=True, exist_ok=True)
    scheduler_options = {"dashboard_address": None}
    worker_args = ["--nthreads", "1"]  # one run per worker; the job's cores are the run's
    if d.interface:
        scheduler_options["interface"] = d.interface
    return cls(
        queue=d.queue,
        account=d.account,
        cores=d.cores,
        processes=1,
        memory=d.memory,
        walltime=d.walltime,
        job_name=job_name(results),
        job_extra_directives=list(d.job_directives),
        job_script_prologue=list(d.job_prologue),
        python=d.python or sys.executable,
        interface=d.interface,
        scheduler_options=scheduler_options,
        worker_extra_args=worker_args,
        log_directory=str(logs),
        death_timeout=DEATH_TIMEOUT_S,
    )


def check_submission(system: str, script: str) -> None:
    """Slurm checks the job script without queueing it (`sbatch --test-only`): a wrong partition, account,
    size or directive is refused here, with Slurm's words."""
    if system != "slurm":
        return
    with tempfile.NamedTemporaryFile("w", suffix=".sh", delete=False) as fh:
        fh.write(script)
    try:
        out = _run(["sbatch", "--test-only", fh.name])
    finally:
        Path(fh.name).unlink(missing_ok=True)
    if out.returncode != 0:
        said = " ".join(line.removeprefix("sbatch: error: ") for line in out.stderr.splitlines() if line.strip())
        raise InfraError(f"Slurm refuses the worker job slamrun would submit: {said}. Fix `distributed:` in the spec")


def wait_for_workers(client, cluster, d: DistributedSpec, name: str) -> None:
    """Wait up to worker_wait_s for the first worker; past it, cancel the jobs and say why they did not start."""
    deadline = time.monotonic() + d.worker_wait_s
    while time.monotonic() < deadline:
        if client.scheduler_info(n_workers=-1)["workers"]:
            return
        time.sleep(0.5)
    jobs = our_jobs(d.cluster, name)
    cancel_jobs(d.cluster, name)
    held = "; ".join(f"job {i} {state.lower()} ({reason})" for i, state, reason in jobs) or "no job is queued"
    raise InfraError(
        f"no worker job started within distributed.worker_wait_s = {d.worker_wait_s:g} s: {held}. slamrun cancelled "
        f"its jobs; no run was started. Look at the queue (squeue -p {d.queue or '<partition>'}), ask for less "
        "(cores, memory, walltime) or raise worker_wait_s"
    )


def start_job_cluster(d: DistributedSpec, results: Path, lanes: int):
    """Cancel what a crashed start of this campaign left, check the job, start the scheduler here and the
    workers as jobs (adaptive between min_workers and max_workers: a job Slurm ends is replaced). Returns
    (cluster, client); the caller closes both, which cancels the jobs."""
    import dask
    from distributed import Client

    # dask closes and replaces a lost worker's job after `lost-worker-timeout` (15 s by default, in which one
    # worker may run the whole rest of a campaign of short runs); a worker that left its job does not come back
    dask.config.set({"distributed.deploy.lost-worker-timeout": f"{REPLACE_WAIT_S}s"})
    preflight(d)
    name = job_name(results)
    cancel_jobs(d.cluster, name)
    cluster = make_job_cluster(d, results, lanes)
    try:
        check_submission(d.cluster, cluster.job_script())
        cluster.adapt(minimum=d.min_workers, maximum=d.max_workers or max(lanes, d.min_workers), interval="1s")
        client = Client(cluster)
        try:
            wait_for_workers(client, cluster, d, name)
        except BaseException:
            client.close()
            raise
    except BaseException:
        cluster.close()
        cancel_jobs(d.cluster, name)
        raise
    return cluster, client
