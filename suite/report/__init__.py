"""What is derived from a run's saved records alone: summary tables, plots, Planner Arena logs."""
