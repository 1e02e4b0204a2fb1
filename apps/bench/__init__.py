"""``mjx-damage bench``: the throughput harness on the K-box table scene (:mod:`tasks.bench_table`).

:mod:`apps.bench.measure` times damage on/off pairs and registry tasks;
:mod:`apps.bench.report` writes the JSON, markdown and PNG; :mod:`apps.bench.cli`
plans a run under a time budget and is the command line
(``benchmarks/throughput.py`` runs it with the committed settings per device).
"""

from apps.bench.cli import main, run_benchmark  # noqa: F401
from apps.bench.measure import batched_initial_state, make_runner, measure_pair, measure_task, peak_memory_bytes  # noqa: F401
from apps.bench.report import plot, report_md, save, summarize  # noqa: F401
