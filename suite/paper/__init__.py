"""Published experiments reproduced on the suite's planners (`python -m suite paper NAME`)."""
