"""The benchmark harness (``make bench``), kept in the repository, out of the installed package:
:mod:`benchmarks.harness` measures, :mod:`benchmarks.command` is ``apf-mpc bench`` (registered by
``benchmarks/study/bench.yaml``), :mod:`benchmarks.bench_aggregate` times the sweep aggregation.
The report reads the typed result (:class:`pipeline.studies.results.bench.BenchResult`) only."""
