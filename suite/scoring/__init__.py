"""Scoring a validated path identically for every planner: the validator, TOPP-RA timing, the metrics
and their registry (`definitions`)."""
