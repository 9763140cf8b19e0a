"""``clrt bench``: the paper's experiments, rerun (the developer benchmarks are the repository's benchmarks/)."""
