"""Running trials: one trial function, the runner that feeds it, the executors, and the records."""
