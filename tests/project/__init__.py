"""Tests of the project as a whole: README, docs, CI, examples and benchmarks, imports and public names."""
