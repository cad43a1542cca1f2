"""Tests of `fmu_build.study`, the parameter studies."""
