"""Tests of `fmu_build.spec`: reading, checking and refusing model specs."""
