"""Planning problems: the paper's pick-and-place cycle turned into named problems with shared goals."""
