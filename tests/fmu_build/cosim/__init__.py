"""Tests of `fmu_build.cosim`, the co-simulation master."""
