"""Studies of the Monte Carlo engine itself (no paper): throughput."""
