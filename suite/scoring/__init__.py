"""Scoring a validated path identically for every planner: TOPP-RA timing, the metrics and their
registry (`definitions`), and re-scoring a saved run's paths (`rescore`)."""
