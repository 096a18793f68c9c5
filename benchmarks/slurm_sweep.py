"""Run a sweep on a SLURM cluster with dask-jobqueue (``pip install -e '.[cluster]'``).

Usage, on the cluster's login node, in the environment where ``persuasive`` is installed
(the batch jobs must see the same environment, e.g. a shared home or a module/conda env)::

    python benchmarks/slurm_sweep.py GRID.toml --out results/my-sweep --jobs 8 \\
        --cores 16 --memory 32GB --walltime 02:00:00 [--queue PARTITION] [--account NAME]

``--print-job-script`` prints the batch script each job would run (no job is submitted).

Each SLURM job runs ``--cores`` Dask worker processes of one thread each (the compiled kernels
hold the GIL, so threads would not run in parallel). The sweep is the same as
``persuasive sweep``: the grid is validated first, then chunks are sent to the workers as
they free up and every finished chunk is written by this process into ``--out``, so the jobs
need no access to that folder. Run the same command again to resume after a crash, a
cancelled job or a reached wall time: finished chunks are skipped.

``--smoke`` checks this script without SLURM: it runs the sweep on a 2-process local cluster
through the same client API.
"""

from __future__ import annotations

import argparse
import contextlib
import sys

from persuasive import sweep
from persuasive.sweep.runner import local_client


def _slurm_client(args: argparse.Namespace):
    from dask_jobqueue import SLURMCluster
    from distributed import Client

    cluster = SLURMCluster(
        cores=args.cores,  # one job: --cores CPUs ...
        processes=args.cores,  # ... as that many worker processes of one thread each
        memory=args.memory,  # per job, shared by its workers (a sweep holds little)
        walltime=args.walltime,
        queue=args.queue,
        account=args.account,
        interface=args.interface,  # the network the compute nodes reach this node on
        scheduler_options={"dashboard_address": None},
    )
    if args.print_job_script:
        print(cluster.job_script())
        cluster.close()
        sys.exit(0)
    cluster.scale(jobs=args.jobs)  # or cluster.adapt(minimum_jobs=1, maximum_jobs=args.jobs)
    client = Client(cluster)
    client.wait_for_workers(1, timeout=args.wait)  # jobs may wait in the queue
    return cluster, client


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("grid", help="grid TOML file (see 'persuasive sweep --help')")
    parser.add_argument("--out", required=True, help="sweep folder")
    parser.add_argument("--jobs", type=int, default=4, help="SLURM jobs [4]")
    parser.add_argument("--cores", type=int, default=8, help="CPUs (= workers) per job [8]")
    parser.add_argument("--memory", default="16GB", help="memory per job [16GB]")
    parser.add_argument("--walltime", default="01:00:00", help="wall time per job")
    parser.add_argument("--queue", default=None, help="SLURM partition")
    parser.add_argument("--account", default=None, help="SLURM account")
    parser.add_argument("--interface", default=None,
                        help="network interface of the scheduler, e.g. ib0 [default route]")
    parser.add_argument("--print-job-script", action="store_true",
                        help="print the SLURM job script dask-jobqueue would submit, and exit")
    parser.add_argument("--wait", type=float, default=600.0,
                        help="seconds to wait for the first worker [600]")
    parser.add_argument("--chunk", type=int, default=None, help="runs per chunk")
    parser.add_argument("--force", action="store_true", help="replace another sweep")
    parser.add_argument("--smoke", action="store_true",
                        help="use a local 2-process cluster instead of SLURM")
    args = parser.parse_args(argv)

    grid = sweep.Grid.from_toml(args.grid)  # fails here, before any job is submitted
    with contextlib.ExitStack() as stack:
        if args.smoke:  # the project's own local cluster: two workers from the fork server
            client = stack.enter_context(local_client(2))
        else:
            cluster, client = _slurm_client(args)
            stack.callback(cluster.close)
            stack.callback(client.close)  # closed first
        summary = sweep.run(grid, args.out, client=client, chunk=args.chunk, force=args.force)
    print(f"{summary.finished} of {summary.runs} runs in {args.out}/runs/ "
          f"({summary.ran} run now, {summary.skipped} earlier, {summary.wall_time_s:.0f} s)")
    if summary.failures:
        print(f"{len(summary.failures)} run(s) failed (see {args.out}/failed/); run the same "
              "command again to retry them", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
