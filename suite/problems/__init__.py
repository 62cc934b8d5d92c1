"""Planning problems: the paper's pick-and-place cycle turned into named problems with shared goals."""

#: The shipped dataset every command uses unless told otherwise, and the tier `compare` runs.
DEFAULT_DATASET = "recycle-v3.1"
DEFAULT_TIER = f"{DEFAULT_DATASET}:quick"
