"""Scoring a validated path identically for every planner: TOPP-RA timing and the metrics."""
