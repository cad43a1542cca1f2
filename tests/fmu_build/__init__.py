"""Tests of `fmu_build`: the FMU interface table, the ecos host lookup, FMI values."""
