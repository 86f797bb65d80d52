"""Benchmark the controller step against the solver's floor: ``make bench`` (``apf-mpc bench``
with this folder on ``$PIPELINE_STUDIES`` and the repository on ``PYTHONPATH``; the harness is
not part of the installed package, the report reads its typed result,
:class:`pipeline.studies.results.bench.BenchResult`).

The command: its options, then :func:`benchmarks.harness.run_benchmark` through the command
layer (:func:`pipeline.commands.run_command`); it draws the scaling plot and prints the headline
figures.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from benchmarks import harness as study
from pipeline.commands import CommandError, output_folder, run_command
from pipeline.studies.results.base import written
from pipeline.studies.results.bench import SCALING_STEM

__all__ = ["main"]

#: The headline figures the command prints (``bench_summary.json`` holds them all).
HEADLINE = ("closed_loop_over_floor", "step_over_floor", "step_over_sparse_floor",
            "step_over_sparse_floor_daqp", "step_over_sparse_floor_path",
            "step_over_sparse_floor_path_daqp", "step_over_sparse_floor_cpu",
            "outside_qp_us_per_step", "qp_us_per_step", "outside_qp_over_qp",
            "outside_qp_over_qp_daqp", "outside_qp_over_qp_python_kernels", "setup_ms",
            "compiles_per_family", "family_scenarios_per_s", "family_member_over_sparse_floor",
            "family_member_over_sparse_floor_daqp", "multiverse_member_reads_per_member",
            "install_over_pip", "member_cache_reuse", "member_cache_resimulated",
            "tune_core_utilisation", "coordinator_ms_per_trial", "pruned_over_unpruned_members",
            "engine_members_per_cpu_s_over_member_loop")


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.command``: ``apf-mpc bench`` (registered from this folder)."""
    from pipeline.cli import main as apf_mpc

    return apf_mpc(["bench", *(sys.argv[1:] if argv is None else argv)],
                   extra_studies=(Path(__file__).resolve().parent,))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc bench``'s arguments."""
    parser.add_argument("--out", type=output_folder, default=Path("reports/bench"))
    parser.add_argument("--steps", type=int, default=40, help="inputs per configuration")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true",
                        help="a minute or so: N=10 and 1 obstacle, fewer repeats and members, "
                             "no install or tune measurement")
    parser.add_argument("--smoke", action="store_true",
                        help="with --quick: each measurement at its smallest size, every figure "
                             "still written, none worth reading (the test suite's run)")
    parser.add_argument("--family-size", type=int, default=200)


def run(args: argparse.Namespace) -> int:
    """The benchmark as ``args`` say, through the command layer."""
    return run_command(lambda: _bench(args))


#: each option's allowed integers, checked before any measurement (``--steps 0`` ran 15 s of
#: benchmark and then failed with a traceback)
OPTION_RANGES = (("steps", 1, 100_000), ("repeats", 1, 1_000), ("family_size", 1, 100_000))


def _bench(args) -> int:
    from pipeline.reporting.figures import bench_scaling_figure, save_figure
    from pipeline.store.manifest import refuse_other_record

    for key, low, high in OPTION_RANGES:
        value = getattr(args, key)
        if not low <= value <= high:
            raise CommandError(f"error: --{key.replace('_', '-')}={value} is invalid; allowed: "
                               f"an integer in [{low}, {high}]")
    if args.smoke and not args.quick:
        raise CommandError("error: --smoke is invalid without --quick; allowed: --quick --smoke")
    if args.out.exists() and not args.out.is_dir():
        raise CommandError(f"error: --out={args.out} is invalid; allowed: a folder (new, or "
                           "one the benchmark wrote before), not a file")
    refuse_other_record(args.out, ("bench",))
    result = study.run_benchmark(args.out, args.steps, args.repeats, args.quick,
                                 args.family_size, args.smoke)
    save_figure(bench_scaling_figure(result.lateral), written(result.folder), SCALING_STEM)
    summary = result.summary
    print(json.dumps({key: summary.get(key) for key in HEADLINE}, indent=1))
    print(json.dumps({"path_frame": summary["path_frame"]}, indent=1))
    print(json.dumps({"lateral_N10_1obs": summary["lateral"][0], "peers": summary["peers"],
                      "pipeline": summary["pipeline"],
                      "n50_over_n10": summary["n50_over_n10_direct"]}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
