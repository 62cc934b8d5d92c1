"""Running trials: one trial function, the runner that feeds it, the executors, the records, dataset
building and re-scoring a saved run."""
