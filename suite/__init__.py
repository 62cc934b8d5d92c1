"""The orchestrator: everything above the lower layers (`scenes`, `perception`, `planners`).

Subpackages, in the order data flows through them:

- `suite.problems`: grasps -> the pick-and-place cycle's planning problems (shared goal IK).
- `suite.run`: trials, the runner, executors (local pool, Dask), the trial records.
- `suite.scoring`: the same validation, TOPP-RA timing and metrics for every planner's path.
- `suite.report`: summary tables, plots and the Planner Arena export, from saved records alone.
- `suite.execution`: the timed plans executed in a Drake physics simulation.
- `suite.bench`: speed figures (benchmarks report numbers; tests assert behaviour).
- `suite.cli`: `python -m suite ...`, one module per command.
"""
