"""Bring your own planner: a dataset's problems exported as plain files (problems, JSON Schema,
robot model files) and an external planner's paths imported as ordinary trial records, judged by
the same validator, TOPP-RA timing and metrics as the suite's own trials (`suite.run.trial`)."""
